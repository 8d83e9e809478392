within TrackingBox;
package Benches "Test benches: a plant model and a digital twin each"
  annotation (Documentation(info="<html>
<p>Four benches, each with a <code>Plant</code> (stands in for the physical
process: degraded parameters, quadratic curves, effects the twin lacks) and a
<code>Twin</code> (the simulator to be tracked), with identical top-level
inputs and outputs (the twin adds correction-flow inputs for state
compensation where it has levels), and a <code>Validation</code> package
with one wrapper per model that binds the inputs to functions of time. Both
extend a partial model in <code>BaseClasses</code> that holds the structure
with the twin's values and, through the component classes, the bounds of the
trackable parameters; <code>Plant</code> overrides values with plain
modifiers.</p>
<table border=\"1\" cellspacing=\"0\" cellpadding=\"3\">
<tr><th>bench</th><th>process</th><th>states</th><th>tracked in the twin</th></tr>
<tr><td><code>HeatExchanger</code></td><td>counter-flow water/water exchanger,
10 cells per side; inputs: inlet temperatures and flows</td><td>20</td>
<td><code>hx.kht</code> 500..1500 W/(m2.K)</td></tr>
<tr><td><code>HeatProduction</code></td><td>water circuit: preheating,
storage and make-up tanks, two pumps, heating unit, exchanger to an external
cold stream, six PI controllers</td><td>29</td>
<td>heat-transfer coefficients of <code>HU300</code> and <code>HEX300</code>,
four pipe coefficients, four valve capacities, two pump design points</td></tr>
<tr><td><code>Evaporator</code></td><td>last effect of a black-liquor
evaporator at 1/10 scale: effect, flash tank, condensate tank, four
loops</td><td>21 (twin)</td><td>fouling <code>effect.Rf</code>,
boiling-point offset <code>effect.dBPR</code>, clean coefficient
<code>effect.U0</code>, valve capacities, pump curve</td></tr>
<tr><td><code>EvaporatorTrain</code></td><td><code>N</code> effects
(default 7) with backward feed, vapour headers and a condensate
cascade</td><td>106 (twin, N = 7)</td><td>per effect <code>Rf</code>,
<code>dBPR</code>, <code>U0</code>; steam vents and heat losses of the
whole train; valve and pump wear</td></tr>
</table>
<p>The <code>Hidden</code> packages of the first two benches hold plant
variants with one effect the twin does not have (exponential fouling, a heat
loss, a leak, a drifting or lagging sensor, a bypass), the cases of the
diagnosis stage's hidden-effect suite.</p>
</html>"));
end Benches;
