within TrackingBox.Blocks;
block StateCompensation "Correction flow that keeps a twin's level on the plant's: gain*(measured - simulated), with hold"
  parameter Real k(min = 0) = 1 "Gain: correction per unit of level difference (e.g. kg/s per m)";
  parameter TrackingBox.Units.Time Te(min = 1e-9) = 1 "Time constant of the error memory (a tenth of the sample time)";
  parameter Real y_start = 0 "Correction at the start";
  parameter Boolean use_hold_in = true "= true to enable the input hold";
  TrackingBox.Interfaces.RealInput u_s "Measured level (plant)"
    annotation (Placement(transformation(extent = {{-140, -20}, {-100, 20}})));
  TrackingBox.Interfaces.RealInput u_m "Simulated level (twin)"
    annotation (Placement(transformation(origin = {0, -120}, extent = {{-20, -20}, {20, 20}}, rotation = 90)));
  TrackingBox.Interfaces.RealInput hold if use_hold_in "Hold: > 0.5 freezes the correction"
    annotation (Placement(transformation(origin = {-60, 120}, extent = {{-20, -20}, {20, 20}}, rotation = 270)));
  TrackingBox.Interfaces.RealOutput y "Correction flow into the twin"
    annotation (Placement(transformation(extent = {{100, -10}, {120, 10}})));
  Real e "Level difference u_s - u_m";
  Real eMem(start = 0, fixed = true) "Error memory: the difference lagged by Te";
  Real m(start = y_start, fixed = true) "Correction";
protected
  TrackingBox.Interfaces.RealInput hold_internal "Used hold signal";
equation
  connect(hold, hold_internal);
  if not use_hold_in then
    hold_internal = 0;
  end if;
  e = u_s - u_m;
  der(eMem) = noEvent(if hold_internal > 0.5 then 0 else (e - eMem)/Te);
  der(m) = noEvent(if hold_internal > 0.5 then 0 else k*(e - eMem)/Te);
  y = m;
  annotation (
    Icon(coordinateSystem(extent = {{-100, -100}, {100, 100}}), graphics = {
      Rectangle(extent = {{-100, 100}, {100, -100}}, lineColor = {0, 0, 127}, fillColor = {255, 255, 255},
        fillPattern = FillPattern.Solid),
      Polygon(points = {{-60, -60}, {60, -60}, {60, 10}, {-60, 10}, {-60, -60}}, lineColor = {0, 128, 255},
        fillColor = {170, 213, 255}, fillPattern = FillPattern.Solid),
      Line(points = {{-80, 30}, {80, 30}}, color = {0, 0, 127}, pattern = LinePattern.Dash),
      Text(extent = {{-60, 90}, {60, 50}}, textString = "k·Δh"),
      Text(extent = {{-150, 150}, {150, 110}}, textString = "%name", textColor = {0, 0, 255})}),
    Documentation(info = "<html>
<p>Direct state compensation: a correction flow <code>y</code> that keeps a
twin's level (an integrating state) on the plant's. Without hold the
correction follows <code>k (u_s - u_m)</code> (lagged by <code>Te</code>):
<code>dm/dt = k (e - eMem)/Te</code>, <code>der(eMem) = (e - eMem)/Te</code>, so
<code>m - k eMem</code> stays constant and <code>m = k e</code> from a zero start.
A proportional law, because a purely integral correction of an integrating
level would oscillate without damping.</p>
<p><b>Hold</b> (<code>hold &gt; 0.5</code>, only with <code>use_hold_in</code>):
the correction and the error memory are frozen together, so <code>m = k eMem</code>
at every time, and on release the correction follows <code>k (u_s - u_m)</code>
again (within <code>Te</code>). A memory that kept following the difference
through a hold would re-base the law there: the correction would keep the
difference at the release as a permanent flow into the twin.</p>
<p><code>trackingbox.tracking.controllers.StateCompensator</code> is the exact
discretisation of this law for a difference held constant over each sample
period (<code>interpolation=\"zoh\"</code>) or linear between samples
(<code>interpolation=\"linear\"</code>, the tracking runtime's default: how
this block sees an interpolated measurement and a continuous twin level).</p>
</html>"));
end StateCompensation;
