within TrackingBox;
package Fluid "Thermal-fluid components for water networks"
  annotation (Documentation(info="<html>
<p>Lumped components for liquid water with directed flow from
<code>port_a</code> to <code>port_b</code> (see <code>Interfaces.FluidPort</code>).
Pressures are piezometric; only tanks have an elevation. Properties come from
<code>Media.Water</code>.</p>
<p>Every quantity that may be tracked (heat-transfer coefficients, pressure-loss
coefficients, valve capacity, pump design flow and pressure rise) offers the
conditional-input pattern: <code>parameter Boolean use_X_in = false</code> and
<code>RealInput X_in if use_X_in</code>; when the flag is set, the input
replaces the parameter.</p>
<p>Pipes and pumps have a structural parameter <code>quadratic</code>:
quadratic pressure-loss and pump curves for a plant model, linear curves for a
twin. Both agree at the design point. The linear law is by default the secant
through zero flow (pipe) or the shut-off point (pump); with
<code>tangent = true</code> it is the tangent at the design point (same value
and slope there), the better linear model near the operating point.</p>
</html>"));
end Fluid;
