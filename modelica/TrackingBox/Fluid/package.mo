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
quadratic pressure-loss and pump curves for a plant model, linear (secant)
curves, equal at the design point, for a twin.</p>
</html>"));
end Fluid;
