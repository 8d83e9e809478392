within TrackingBox.Blocks.Validation;
model PIHoldAndLimits "PI controller on a first-order process: setpoint step, saturation and hold"
  extends TrackingBox.Icons.Example;
  TrackingBox.Blocks.PI con(k=2, Ti=50, Tt=10, yMin=0, yMax=1, y_start=0.2) "Controller";
  Real x(start=0, fixed=true) "First-order process output";
equation
  con.u_s = 0.5 + 0.4*smooth(0, if time > 200 then 1 else 0);
  con.u_m = x;
  con.hold = smooth(0, if time > 600 and time < 900 then 1 else 0);
  der(x) = (con.y - x)/60;
  annotation (experiment(StopTime=1500, Tolerance=1e-6), Documentation(info="<html>
<p>Process <code>60 s &middot; dx/dt = y - x</code>. The setpoint steps from
0.5 to 0.9 at 200 s (the loop settles, output below 1); the controller is
held from 600 s to 900 s (output constant) and released afterwards.</p>
</html>"));
end PIHoldAndLimits;
