within TrackingBox.Blocks;
block ParameterController "Scaled PI parameter controller: output 0..100 % of the parameter's bounds, direction, clamp with anti-windup, hold"
  parameter Real yMin = 0 "Lower bound of the parameter (0 % output), in the parameter's unit";
  parameter Real yMax = 1 "Upper bound of the parameter (100 % output), in the parameter's unit";
  parameter Real y_start = yMin "Parameter value at the start (clamped into the bounds)";
  parameter Real span(min = 1e-12) = 1 "Range of the tracking variable that is 100 % error, in the variable's unit";
  parameter Real kp(unit = "1", min = 0) = 1 "Proportional gain, % output per % error";
  parameter TrackingBox.Units.Time Ti(min = 1e-9) = 100 "Integral time";
  parameter TrackingBox.Units.Time Te(min = 1e-9) = 1 "Time constant of the error memory (a tenth of the sample time)";
  parameter Boolean reverseActing = false "= true for reverse action (the pair's gain is negative)";
  TrackingBox.Interfaces.RealInput u_s "Measured value of the tracking variable (plant)"
    annotation (Placement(transformation(extent = {{-140, -20}, {-100, 20}})));
  TrackingBox.Interfaces.RealInput u_m "Simulated value of the tracking variable (twin)"
    annotation (Placement(transformation(origin = {0, -120}, extent = {{-20, -20}, {20, 20}}, rotation = 90)));
  TrackingBox.Interfaces.RealInput hold "Hold: > 0.5 freezes the output, nothing integrates"
    annotation (Placement(transformation(origin = {-60, 120}, extent = {{-20, -20}, {20, 20}}, rotation = 270)));
  TrackingBox.Interfaces.RealOutput y "Tracked parameter value"
    annotation (Placement(transformation(extent = {{100, -10}, {120, 10}})));
  Real e(unit = "1") "Control error in % of span";
  Real eMem(unit = "1", start = 0, fixed = true) "Error memory: the error lagged by Te (%)";
  Real rate(unit = "1/s") "Rate of the output before clamping (% per s)";
  Real u(unit = "1", start = min(max(100*(y_start - yMin)/(yMax - yMin), 0), 100), fixed = true)
    "Output in % of the bounds";
protected
  parameter Real direction(unit = "1") = if reverseActing then -1 else 1 "+1 direct, -1 reverse action";
equation
  e = 100*(u_s - u_m)/span;
  der(eMem) = (e - eMem)/Te;
  rate = direction*kp*(e/Ti + (e - eMem)/Te);
  der(u) = noEvent(if hold > 0.5 or (u >= 100 and rate > 0) or (u <= 0 and rate < 0) then 0 else rate);
  y = yMin + min(max(u, 0), 100)/100*(yMax - yMin);
  annotation (
    Icon(coordinateSystem(extent = {{-100, -100}, {100, 100}}), graphics = {
      Rectangle(extent = {{-100, 100}, {100, -100}}, lineColor = {0, 0, 127}, fillColor = {255, 255, 255},
        fillPattern = FillPattern.Solid),
      Line(points = {{-80, -70}, {-80, -20}, {60, 50}, {80, 50}}, color = {0, 0, 127}),
      Line(points = {{-90, 60}, {90, 60}}, color = {192, 192, 192}, pattern = LinePattern.Dash),
      Line(points = {{-90, -70}, {90, -70}}, color = {192, 192, 192}, pattern = LinePattern.Dash),
      Text(extent = {{-60, 90}, {90, 70}}, textString = "PI %"),
      Text(extent = {{-150, 150}, {150, 110}}, textString = "%name", textColor = {0, 0, 255})}),
    Documentation(info = "<html>
<p>Parameter controller of a tracking box: the plant's measurement
<code>u_s</code> is the setpoint, the twin's simulated value <code>u_m</code> the
process value, a twin parameter the output <code>y</code>.</p>
<ul>
<li><b>Scaling</b>: the error is <code>e = 100 (u_s - u_m)/span</code> in %; the
output <code>u</code> is 0..100 % and maps onto the bounds,
<code>y = yMin + u/100 (yMax - yMin)</code>. So <code>kp</code> is dimensionless
(% per %).</li>
<li><b>Law</b> (velocity-form PI, continuous):
<code>du/dt = d kp (e/Ti + (e - eMem)/Te)</code> with
<code>der(eMem) = (e - eMem)/Te</code>, <code>d = +1</code> (direct) or
<code>-1</code> (<code>reverseActing</code>). The second term is the
proportional action: for a step of <code>e</code> it moves <code>u</code> by
<code>kp</code> times the step within a few <code>Te</code>. Use
<code>Te</code> = a tenth of the tracking sample time.</li>
<li><b>Clamp and anti-windup</b>: <code>u</code> stops at 0 and 100 % while the
rate points out of the range (conditional integration), so a saturated
controller stores nothing and leaves the bound as soon as the rate changes sign.</li>
<li><b>Hold</b> (<code>hold &gt; 0.5</code>): the output is frozen and nothing
integrates; the error memory keeps following the error, so on release the
proportional term sees no step (bumpless resume).</li>
</ul>
<p>There are no events, discrete variables or <code>pre()</code>, so the block
compiles on the embedded path. <code>trackingbox.tracking.controllers.ScaledPI</code>
is the exact discretisation of this law for two error signals: held constant
over each sample period (<code>interpolation=\"zoh\"</code>), or linear from
one sample to the next (<code>interpolation=\"linear\"</code>). The second is
what this block sees in a tracking box: the measurement is interpolated
linearly between its samples and the twin's output is continuous. The Python
tracking runtime uses it by default, so the compiled box and the runtime agree
closely. Where the twin answers the parameter partly within a sample, the loop
closes within the sample in this block, so the runtime integrates the
controller with the twin over sub-steps of the sample (chosen from the loop
gain within one sample, measured on the twin). Tests drive both with the same recorded error
sequence, held and interpolated, and require the same outputs.
The error memory starts at 0, in the block and in the Python class: without a
start-up hold the proportional action acts on the whole initial error; start
the block on hold for a few <code>Te</code> (the start-up hold of a tracking
box) and it starts without a kick.</p>
</html>"));
end ParameterController;
