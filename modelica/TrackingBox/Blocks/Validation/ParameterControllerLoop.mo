within TrackingBox.Blocks.Validation;
model ParameterControllerLoop "Parameter controller tracking the gain of a first-order twin: convergence, saturation, hold and resumption"
  extends TrackingBox.Icons.Example;
  parameter TrackingBox.Units.Time tau = 100 "Time constant of plant and twin";
  Real kTrue(unit = "1") "Gain of the plant (the truth to track)";
  Real xPlant(unit = "1", start = 1.0, fixed = true) "Plant output (the measurement)";
  Real xTwin(unit = "1", start = 1.0, fixed = true) "Twin output (the simulated value)";
  Real holdSignal(unit = "1") "1 while the controller is held";
  TrackingBox.Blocks.ParameterController con(yMin = 0.5, yMax = 3.0, y_start = 1.0, span = 2.5, kp = 1.0,
    Ti = 100, Te = 1) "Tracks the twin's gain"
    annotation (Placement(transformation(extent = {{-10, -10}, {10, 10}})));
equation
  kTrue = noEvent(if time < 2000 then 1.5 else if time < 3500 then 4.0 else 1.0);
  holdSignal = noEvent(if time >= 3500 and time < 4000 then 1.0 else 0.0);
  tau*der(xPlant) = kTrue - xPlant;
  tau*der(xTwin) = con.y - xTwin;
  con.u_s = xPlant;
  con.u_m = xTwin;
  con.hold = holdSignal;
  annotation (experiment(StopTime = 6000, Tolerance = 1e-8), Documentation(info = "<html>
<p>Plant and twin are <code>tau dx/dt = k - x</code>; the controller adjusts
the twin's gain (bounds 0.5..3, span = |dx/dk| (3 - 0.5) = 2.5, SIMC-like
settings <code>kp = 1</code>, <code>Ti = tau</code>). The plant's gain is 1.5
until 2000 s (the twin's converges to it), 4.0 until 3500 s (out of bounds:
the output sits at 3 without winding up), then 1.0. From 3500 s to 4000 s the
controller is held (output frozen at 3); afterwards it resumes and converges
to 1.0.</p>
</html>"));
end ParameterControllerLoop;
