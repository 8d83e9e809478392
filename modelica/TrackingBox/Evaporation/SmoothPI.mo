within TrackingBox.Evaporation;
block SmoothPI "PI controller with a smooth tanh output limit 0..1, back-calculation anti-windup and hold"
  parameter Real k = 1 "Gain (negative for reverse action)";
  parameter TrackingBox.Units.Time Ti(min=1e-3) = 300 "Integral time";
  parameter TrackingBox.Units.Time Tt(min=1e-3) = 60 "Tracking time constant of the anti-windup";
  parameter TrackingBox.Units.Time Tf(min=1e-3) = 1 "Time constant of the error filter";
  parameter Real y_start(min=0.001, max=0.999) = 0.5 "Initial output for zero error";
  parameter Boolean use_hold_in = false "= true to enable the input hold";
  TrackingBox.Interfaces.RealInput u_s "Setpoint";
  TrackingBox.Interfaces.RealInput u_m "Measurement";
  TrackingBox.Interfaces.RealInput hold if use_hold_in "Hold: > 0.5 freezes the controller (output held)";
  TrackingBox.Interfaces.RealOutput y(unit="1") "Output, 0..1";
  Real e "Control error u_s - u_m";
  Real eF(start=0, fixed=true) "Filtered error";
  Real I(start=(0.5 + 0.25*log(y_start/(1 - y_start)))/k, fixed=true) "Integral state";
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
  der(eF) = run*(e - eF)/Tf;
  v = k*(eF + I);
  der(I) = run*(eF/Ti + (y - v)/(k*Tt));
  y = 0.5 + 0.5*tanh(2*(v - 0.5));
  annotation (Documentation(info="<html>
<p>The smooth PI of the evaporator notes (section 3):
<code>v = k&middot;(e_f + I)</code>,
<code>dI/dt = e_f/Ti + (y - v)/(k&middot;Tt)</code>,
<code>y = 1/2 + 1/2&middot;tanh(2(v - 1/2))</code> (slope 1 at mid-range, never
outside 0..1, no events). The error is filtered (<code>Tf</code>) so that the
output is a function of states and can be held: the input <code>hold</code>
above 0.5 stops both states (through a smooth switch), below 0.5 the
controller resumes without a bump. A negative <code>k</code> gives reverse
action (a level loop on an outlet valve).</p>
</html>"));
end SmoothPI;
