within TrackingBox.Benches.HeatExchanger;
package BaseClasses "Shared structure of plant and twin"
  annotation (Documentation(info="<html>
<p><code>PartialBench</code> holds what plant and twin share: the four
boundary inputs (inlet temperatures and flows), the two outlet temperatures,
the sources, sinks and the exchanger with the twin's values.
<code>TrackedHeatExchanger</code> is <code>Fluid.HeatExchanger</code> with the
bench's bounds on the tracked coefficient <code>kht</code>.</p>
</html>"));
end BaseClasses;
