within;
package TrackingBox "Thermal-fluid and evaporation models and test benches for tracking simulators"
  annotation (version="0.1.0", Documentation(info="<html>
<p>The Modelica library of the trackingbox toolchain, self-contained (it does
not use the Modelica Standard Library, so it carries no <code>uses</code>
annotation) and written for what the embedded compiler supports: no events,
no discrete variables, smooth laws throughout.</p>
<ul>
<li><code>Units</code>: SI types (K, Pa, kg/s, W/(m2.K), ...).</li>
<li><code>Interfaces</code>: signal connectors <code>RealInput</code>,
<code>RealOutput</code>; the water port <code>FluidPort</code> (pressure, mass
flow, temperature; directed flow from <code>port_a</code> to
<code>port_b</code>, the upstream side sets <code>T</code>).</li>
<li><code>Media</code>: liquid water, the water/steam saturation line of
IAPWS-IF97, and kraft black liquor as a function of its dry solids.</li>
<li><code>Blocks</code>: <code>PI</code> with limits, anti-windup, hold and
manual mode; <code>ParameterController</code> and
<code>StateCompensation</code>, the tracking laws a generated tracking box
instantiates.</li>
<li><code>Fluid</code>: pipe, valve, pump, open tank, heating unit and
counter-flow heat exchanger for water networks, sources and sinks.</li>
<li><code>Evaporation</code>: falling-film effect, flash and condensate tanks,
liquor valve and pump, level transmitter, dry-solids meter, smooth PI.</li>
</ul>
<p>Every trackable quantity follows the conditional-input pattern of the
Modelica Standard Library: <code>parameter Boolean use_X_in = false</code>
and <code>RealInput X_in if use_X_in</code>, so a tracked model only sets the
flag and connects the input.</p>
<p><b>Benches</b> (<code>Benches</code>): each has a <code>Plant</code> that
stands in for the process (degraded parameters, its own effects), a
<code>Twin</code> (the simulator to be tracked: design values, the parameters
to track with their bounds), the same inputs and outputs, and runnable
<code>Validation</code> models.</p>
<ol>
<li><code>HeatExchanger</code>: a counter-flow water/water exchanger, ten cells
per side; one trackable coefficient <code>hx.kht</code> (plant 910, twin 1000
W/(m2.K)).</li>
<li><code>HeatProduction</code>: a water circuit with three tanks, two pumps,
a heating unit and an exchanger to a heat consumer under six PI controllers;
fourteen trackable parameters (heat-transfer and pipe coefficients, valve
capacities, pump design points), quadratic curves in the plant and linear
ones in the twin, correction flows for the tank levels.</li>
<li><code>Evaporator</code>: the last effect of a black-liquor evaporation
plant at 1/10 scale, the case of the source thesis, with fouling, scaling, a
boiling-point offset, a steam vent, heat losses and worn valves and pump in
the plant.</li>
<li><code>EvaporatorTrain</code>: a whole train of <code>N</code> such
effects (7 by default) with backward feed, vapour headers and a condensate
cascade, degraded effect by effect in the plant.</li>
</ol>
<p>Version 0.1.0 ships with trackingbox 0.1.0 (<code>modelica/README.md</code>
has the conventions and each bench's inputs, outputs and parameters).</p>
</html>"));
end TrackingBox;
