within TrackingBox.Fluid;
package Validation "Validation models for the fluid components"
  annotation (Documentation(info="<html>
<p>Runnable models of the water components:</p>
<ul>
<li><code>HeatedLoop</code>: tank, pump, pipe, valve, heating unit and heat
exchanger in a closed loop; the flow must satisfy the hand balance of the
pump, pipe and valve laws with the tank's hydrostatic head, the level must not
move, and the heat balance must close.</li>
<li><code>CurveLaws</code>: each pipe and pump law (quadratic, linear secant,
linear tangent) under one ramp of flow, so the curves can be compared at and
away from the design point.</li>
<li><code>DiagnosisHooks</code>: the tank's leak and extra heat loss, the
heating unit's and exchanger's heat losses and a coefficient taken from an
input, all switched on.</li>
</ul>
</html>"));
end Validation;
