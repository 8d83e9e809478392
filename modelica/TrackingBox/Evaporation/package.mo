within TrackingBox;
package Evaporation "Black-liquor evaporation: falling-film effect, flash and condensate tanks, valves, pump, instruments"
  annotation (Documentation(info="<html>
<p>Lumped, smooth and event-free components for a slice of a multi-effect
black-liquor evaporation plant (method and formulas: the evaporator notes,
section 3). Liquid streams (liquor and condensate) use
<code>LiquorPort</code> (pressure, mass flow, dry-solids fraction, temperature;
directed flow from <code>port_a</code> to <code>port_b</code>, the upstream
side sets <code>x</code> and <code>T</code>). Steam and vapour streams use the
water port <code>TrackingBox.Interfaces.FluidPort</code> (saturated vapour,
its enthalpy is <code>hVapour(TSat(p))</code>).</p>
<p>Liquid enthalpy is <code>Media.BlackLiquor.specificEnthalpy(x, T)</code>
everywhere (condensate is liquor with <code>x = 0</code>), vapour enthalpy
<code>Media.Water.Saturation.hVapour(T)</code>. Every vessel keeps the states
<code>M</code>, <code>M_s</code> (dry solids), <code>T</code> and the vapour
mass of its vapour space, and writes its energy balance for the inventory
<code>M&middot;h(x, T)</code> exactly (the term in <code>dx/dt</code> is
kept), so the mass, dry-solids and energy balances of an assembly close to
the solver's tolerance (<code>Validation.SliceBalance</code>).</p>
<p>Non-smooth functions are replaced by <code>Functions.splus</code> (smooth
positive part) and <code>Functions.regRoot</code> (regularised square root).</p>
</html>"));
end Evaporation;
