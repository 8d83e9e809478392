within TrackingBox.Media;
package BlackLiquor "Kraft black liquor as a function of the dry-solids mass fraction"
  annotation (Documentation(info="<html>
<p>Property correlations of kraft black liquor used in evaporator models; the
argument <code>x</code> is the dry-solids (DS) mass fraction, 0..1.
All functions are smooth (no events) and use SI units.</p>
<ul>
<li><code>boilingPointRise(x, p)</code>: Frederick-type boiling-point rise at
atmospheric pressure, <code>6.173 x - 7.48 x^1.5 + 32.747 x^2</code> K, scaled
with pressure by <code>1 + 0.6 (TSat(p) - 373.16 K)/100 K</code>.</li>
<li><code>cp(x, T)</code>: <code>4.216 (1 - x) + (1.675 + 3.31e-3 t) x +
(4.87 - 0.020 t)(1 - x) x^3</code> kJ/(kg.K) with <code>t</code> in degC
(the excess term is the non-ideality of the solution).</li>
<li><code>specificEnthalpy(x, T)</code>: the integral of <code>cp</code> from
0 degC (273.15 K), done analytically, so <code>h = 0</code> at 0 degC for every
<code>x</code> and <code>dh/dT = cp</code> exactly. No heat of dilution.</li>
<li><code>density(x, T, k)</code>: <code>(997 + k x)(1.008 - 0.237e-3 t -
1.94e-6 t^2)</code> kg/m3 (<code>t</code> in degC), with <code>k = 649</code>
kg/m3 by default; 694 is another published value (at x = 0.75 the two give
1484 and 1518 kg/m3 where the temperature factor is 1, near 27.5 degC).</li>
</ul>
<p>The correlations and the values they give are collected in the project's
evaporator notes (section 1). No validity range is published; above about
65 % DS (salt solubility) treat the boiling-point rise as an extrapolation.</p>
</html>"));
end BlackLiquor;
