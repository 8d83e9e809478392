within TrackingBox;
package Media "Medium property functions"
  annotation (Documentation(info="<html>
<p>Property functions of the media used in the library; each medium is a
package of functions, so new properties can be added as further functions
without changing the components.</p>
<ul>
<li><code>Water</code>: liquid water, 0..150 degC (<code>cp</code>, <code>rho</code>,
and an Antoine saturation pair <code>pSat</code>/<code>TSat</code>), and
<code>Water.Saturation</code>: water and steam on the saturation line,
20..200 degC (the IAPWS-IF97 region-4 pair, saturated liquid and vapour
enthalpies, latent heat).</li>
<li><code>BlackLiquor</code>: kraft black liquor as a function of the dry-solids
fraction (boiling-point rise, specific heat, specific enthalpy, density).</li>
<li><code>Validation</code>: a model evaluating every function at given inputs,
for the comparisons with independent references.</li>
</ul>
<p>All functions are smooth and event-free (no <code>if</code>, <code>min</code>,
<code>max</code> or <code>abs</code> in the new packages), in SI units.</p>
</html>"));
end Media;
