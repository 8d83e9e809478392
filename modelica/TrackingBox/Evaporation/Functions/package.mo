within TrackingBox.Evaporation;
package Functions "Smooth helper functions of the evaporation components"
  annotation (Documentation(info="<html>
<p>Smooth functions the evaporation components share instead of
non-differentiable operators, so their models have no events:</p>
<ul>
<li><code>splus(z, eps)</code>: <code>(z + sqrt(z&sup2; + eps&sup2;))/2</code>, a
smooth <code>max(z, 0)</code> (boiling law, mixing weights, output limits);</li>
<li><code>regRoot(dp, delta)</code>: <code>dp/(dp&sup2; + delta&sup2;)^(1/4)</code>,
a signed square root with a finite slope at zero (valve and vapour-line laws);</li>
<li><code>kinematicViscosity(x, T)</code>: the liquor viscosity correlation
used for the shape of the effect's clean coefficient;</li>
<li><code>enthalpyDerivativeX(x, T)</code>: <code>&part;h/&part;x</code> of the
black-liquor enthalpy, for the vessels' exact energy balance.</li>
</ul>
</html>"));
end Functions;
