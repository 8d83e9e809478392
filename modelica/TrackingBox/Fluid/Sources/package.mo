within TrackingBox.Fluid;
package Sources "Boundary conditions"
  annotation (Documentation(info="<html>
<p>Sources set the temperature of the water they deliver (<code>port_b</code>);
sinks (<code>port_a</code>) take the temperature from upstream.</p>
</html>"));
end Sources;
