within TrackingBox.Evaporation;
block SmoothPI "PI controller with a smooth output limit 0..1, back-calculation anti-windup and hold"
  parameter Real k = 1 "Gain (negative for reverse action)";
  parameter TrackingBox.Units.Time Ti(min=1e-3) = 300 "Integral time";
  parameter TrackingBox.Units.Time Tt(min=1e-3) = 60 "Tracking time constant of the anti-windup";
  parameter TrackingBox.Units.Time Tf(min=1e-3) = 1 "Time constant of the error filter";
  parameter Real y_start(min=0.001, max=0.999) = 0.5 "Initial output for zero error";
  parameter Real yEps(min=1e-6) = 1e-3 "Width of the smooth corners of the output limit";
  parameter Boolean use_hold_in = false "= true to enable the input hold";
  TrackingBox.Interfaces.RealInput u_s "Setpoint"
    annotation (Placement(transformation(extent={{-140,-20},{-100,20}})));
  TrackingBox.Interfaces.RealInput u_m "Measurement"
    annotation (Placement(transformation(origin={0,-120}, extent={{-20,-20},{20,20}}, rotation=90)));
  TrackingBox.Interfaces.RealInput hold if use_hold_in "Hold: > 0.5 freezes the controller (output held)"
    annotation (Placement(transformation(origin={-60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealOutput y(unit="1") "Output, 0..1"
    annotation (Placement(transformation(extent={{100,-10},{120,10}})));
  Real e "Control error u_s - u_m";
  Real eF(start=0, fixed=true) "Filtered error";
  Real I(start=y_start/k, fixed=true) "Integral state";
  Real v "Output before the limit";
  Real run(unit="1") "1 in operation, 0 while held (smooth switch)";
protected
  TrackingBox.Interfaces.RealInput hold_internal "Used hold signal";
equation
  connect(hold, hold_internal);
  if not use_hold_in then
    hold_internal = 0;
  end if;
  run = 0.5 - 0.5*tanh((hold_internal - 0.5)/0.05);
  e = u_s - u_m;
  der(eF) = (e - eF)/Tf;
  v = k*(eF + I);
  der(I) = run*(eF/Ti + (y - v)/(k*Tt)) - (1 - run)*(e - eF)/Tf;
  y = TrackingBox.Evaporation.Functions.splus(v, yEps) - TrackingBox.Evaporation.Functions.splus(v - 1, yEps);
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Rectangle(extent={{-100,100},{100,-100}}, lineColor={0,0,127}, fillColor={255,255,255}, fillPattern=FillPattern.Solid), Line(points={{-80,-70},{-80,20},{0,40},{80,60}}, color={0,0,127}), Text(extent={{-40,-20},{80,-80}}, textString="PI"), Text(extent={{-150,150},{150,110}}, textString="%name", textColor={0,0,255})}), Documentation(info="<html>
<p>The smooth PI of the evaporator notes (section 3):
<code>v = k&middot;(e_f + I)</code>,
<code>dI/dt = e_f/Ti + (y - v)/(k&middot;Tt)</code>, with the output limited
smoothly to 0..1 by <code>y = s&#8314;(v) - s&#8314;(v - 1)</code>
(<code>Functions.splus</code>, corner width <code>yEps</code>): linear
(<code>y = v</code>) inside the range, no events. The notes' limit
<code>1/2 + 1/2&middot;tanh(2(v - 1/2))</code> was tried first and dropped: it has
no linear part, so the back-calculation term <code>(y - v)/(k&middot;Tt)</code>
acts everywhere and balances the integral action away from saturation (an
inlet flow loop with setpoint 0.01 kg/s stayed at 0.33 kg/s).</p>
<p>The error is filtered (<code>Tf</code>) so that the output is a function of
states and can be held: while the input <code>hold</code> is above 0.5 (a
smooth switch <code>run</code>), the integral action stops and the integral
state moves opposite to the filtered error, so <code>v</code> and the output
stay constant while <code>e_f</code> keeps following the error; below 0.5
the controller resumes from there without a proportional kick (bumpless). A negative <code>k</code> gives reverse action (a level loop on an
outlet valve).</p>
</html>"));
end SmoothPI;
