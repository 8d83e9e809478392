within TrackingBox.Benches.HeatProduction;
package BaseClasses "Shared structure of plant and twin"
  annotation (Documentation(info="<html>
<p><code>PartialProcess</code> is the whole heat-production process (tanks
T100, T200, T400, pumps, pipes, valves, heating unit HU300, exchanger HEX300,
six PI controllers, inputs and sensor outputs) with the twin's values; plant and
twin extend it. The <code>Tracked...</code> classes are the library's
components with the bench's bounds on the trackable parameters (heat-transfer
coefficients, pipe coefficients, valve capacities, pump design points), so
that plant and twin both keep them.</p>
</html>"));
end BaseClasses;
