within TrackingBox.Blocks;
block PI "PI controller with output limits, anti-windup, hold input and manual mode"
  parameter Real k = 1 "Proportional gain (negative for reverse action)";
  parameter TrackingBox.Units.Time Ti(min=1e-3) = 100 "Integral time";
  parameter TrackingBox.Units.Time Tt(min=1e-3) = 10 "Tracking time constant of the anti-windup back-calculation";
  parameter TrackingBox.Units.Time Tf(min=1e-3) = 1 "Time constant of the error filter of the proportional part";
  parameter Real yMax = 1 "Upper limit of the output";
  parameter Real yMin = 0 "Lower limit of the output";
  parameter Real y_start = 0 "Initial value of the integral part (initial output for zero error)";
  parameter Real manual = 0 "Manual mode: > 0.5 sets the output to yMan";
  parameter Real yMan = 0 "Output in manual mode (set it before switching to manual)";
  parameter Boolean use_hold_in = true "= true to enable the input hold";
  TrackingBox.Interfaces.RealInput u_s "Setpoint"
    annotation (Placement(transformation(extent={{-140,-20},{-100,20}})));
  TrackingBox.Interfaces.RealInput u_m "Measurement"
    annotation (Placement(transformation(origin={0,-120}, extent={{-20,-20},{20,20}}, rotation=90)));
  TrackingBox.Interfaces.RealInput hold if use_hold_in "Hold: > 0.5 freezes the integral part and the output"
    annotation (Placement(transformation(origin={-60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealOutput y "Controller output"
    annotation (Placement(transformation(extent={{100,-10},{120,10}})));
  Real e "Control error u_s - u_m";
  Real eF(start=0, fixed=true) "Filtered error used by the proportional part";
  Real yI(start=y_start, fixed=true) "Integral part";
  Real yUnsat "Output before limitation";
  Real run "1 in normal operation, 0 while held";
protected
  TrackingBox.Interfaces.RealInput hold_internal "Used hold signal";
equation
  connect(hold, hold_internal);
  if not use_hold_in then
    hold_internal = 0;
  end if;
  run = noEvent(if hold_internal > 0.5 then 0 else 1);
  e = u_s - u_m;
  der(eF) = noEvent(if hold_internal > 0.5 then 0 else (e - eF)/Tf);
  yUnsat = k*eF + yI;
  der(yI) = noEvent(if hold_internal > 0.5 then 0 else k*e/Ti + (y - yUnsat)/Tt);
  y = if manual > 0.5 then yMan else min(max(yUnsat, yMin), yMax);
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-100,100},{100,-100}}, lineColor={0,0,127}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Line(points={{-80,-80},{-80,0},{60,60},{80,60}}, color={0,0,127}),
      Line(points={{-90,60},{90,60}}, color={192,192,192}, pattern=LinePattern.Dash),
      Text(extent={{-10,-10},{90,-70}}, textString="PI", textColor={0,0,127}),
      Text(extent={{-150,150},{150,110}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Continuous PI controller <code>y = k*(e_f + 1/Ti*&int;e dt)</code> with
<code>yMin &le; y &le; yMax</code>. The proportional part acts on the error
filtered with time constant <code>Tf</code> (small), so that the output is a
function of states only and can be frozen.</p>
<ul>
<li><b>Anti-windup</b>: back-calculation, the integral part is driven by
<code>(y - yUnsat)/Tt</code> while the output is limited.</li>
<li><b>Hold</b>: the Real input <code>hold</code> (there are no Boolean
variables in this library) freezes the integral part and the filtered error
while <code>hold &gt; 0.5</code>, so the output stays at its last value; below
0.5 the controller resumes without a bump. With
<code>use_hold_in = false</code> the input is removed.</li>
<li><b>Manual mode</b>: the Real parameter <code>manual &gt; 0.5</code> sets the
output to <code>yMan</code> (both are tunable parameters, so a step test can
switch a loop to manual between communication steps); the integral part
tracks <code>yMan</code> through the back-calculation, so returning to
automatic is bumpless.</li>
</ul>
</html>"));
end PI;
