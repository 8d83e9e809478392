within TrackingBox.Media.Water;
package Saturation "Saturated water and steam, 20..200 degC (IAPWS-IF97 region 4 and fitted enthalpies)"
  annotation (Documentation(info="<html>
<p>Properties of water and steam on the saturation line, for evaporators and
steam chests. All functions are smooth (no events) and use SI units
(K, Pa, J/kg).</p>
<ul>
<li><code>pSat(T)</code> and <code>TSat(p)</code>: the explicit saturation-pressure
and saturation-temperature equations of IAPWS-IF97 region 4 (the basic equation
solved for pressure, and its backward form solved for temperature). They agree with
IAPWS-IF97 to rounding (relative error below 1e-8 in pressure, below 1e-6 K in
temperature; the two are inverse to each other to the same accuracy).</li>
<li><code>hLiquid(T)</code>, <code>hVapour(T)</code>: polynomials in
<code>(T - 273.15 K)/100 K</code> least-squares fitted to IAPWS-IF97 saturated
liquid and vapour enthalpies between 20 and 200 degC: within 2 J/kg (liquid)
and 10 J/kg (vapour) there. The reference state is IAPWS's (internal energy
and entropy of the liquid zero at the triple point), so <code>hLiquid</code>
is 0.06 kJ/kg at 0.01 degC, close to the black-liquor enthalpy reference
(<code>BlackLiquor.specificEnthalpy</code> is zero at 0 degC).</li>
<li><code>hfg(T) = hVapour(T) - hLiquid(T)</code>: latent heat, within 11 J/kg.</li>
</ul>
<p>Outside 20..200 degC the enthalpy polynomials are extrapolations; the
saturation pair keeps the accuracy of IF97 from 273.15 K to 647.096 K.
The older <code>Water.pSat</code>/<code>Water.TSat</code> (an Antoine fit,
within 0.3 %) are kept unchanged for the components that use them.</p>
</html>"));
end Saturation;
