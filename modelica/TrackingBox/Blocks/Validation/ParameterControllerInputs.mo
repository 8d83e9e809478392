within TrackingBox.Blocks.Validation;
model ParameterControllerInputs "Parameter controllers (direct and reverse) and a state compensation driven by top-level inputs"
  extends TrackingBox.Icons.Example;
  TrackingBox.Interfaces.RealInput u_s(start = 50.0) "Measured value (plant)"
    annotation (Placement(transformation(extent = {{-140, -20}, {-100, 20}})));
  TrackingBox.Interfaces.RealInput u_m(start = 50.0) "Simulated value (twin)"
    annotation (Placement(transformation(extent = {{-140, -80}, {-100, -40}})));
  TrackingBox.Interfaces.RealInput hold(start = 0.0) "Hold: > 0.5 freezes the controllers"
    annotation (Placement(transformation(extent = {{-140, 40}, {-100, 80}})));
  TrackingBox.Blocks.ParameterController direct(yMin = 800, yMax = 1200, y_start = 1000, span = 2,
    kp = 0.5, Ti = 60, Te = 1) "Direct-acting controller"
    annotation (Placement(transformation(extent = {{-10, 50}, {10, 70}})));
  TrackingBox.Blocks.ParameterController reverse(yMin = 800, yMax = 1200, y_start = 1000, span = 2,
    kp = 0.5, Ti = 60, Te = 1, reverseActing = true) "Reverse-acting controller"
    annotation (Placement(transformation(extent = {{-10, -10}, {10, 10}})));
  TrackingBox.Blocks.StateCompensation comp(k = 5, Te = 1) "State compensation"
    annotation (Placement(transformation(extent = {{-10, -70}, {10, -50}})));
  TrackingBox.Interfaces.RealOutput yDirect "Output of the direct-acting controller"
    annotation (Placement(transformation(extent = {{100, 50}, {120, 70}})));
  TrackingBox.Interfaces.RealOutput yReverse "Output of the reverse-acting controller"
    annotation (Placement(transformation(extent = {{100, -10}, {120, 10}})));
  TrackingBox.Interfaces.RealOutput m "Correction of the state compensation"
    annotation (Placement(transformation(extent = {{100, -70}, {120, -50}})));
equation
  connect(u_s, direct.u_s) annotation (Line(points = {{-120, 0}, {-40, 0}, {-40, 60}, {-14, 60}}, color = {0, 0, 127}));
  connect(u_s, reverse.u_s) annotation (Line(points = {{-120, 0}, {-14, 0}}, color = {0, 0, 127}));
  connect(u_s, comp.u_s) annotation (Line(points = {{-120, 0}, {-40, 0}, {-40, -60}, {-14, -60}}, color = {0, 0, 127}));
  connect(u_m, direct.u_m) annotation (Line(points = {{-120, -60}, {-60, -60}, {-60, 40}, {0, 40}, {0, 48}}, color = {0, 0, 127}));
  connect(u_m, reverse.u_m) annotation (Line(points = {{-120, -60}, {-60, -60}, {-60, -20}, {0, -20}, {0, -12}}, color = {0, 0, 127}));
  connect(u_m, comp.u_m) annotation (Line(points = {{-120, -60}, {-60, -60}, {-60, -80}, {0, -80}, {0, -72}}, color = {0, 0, 127}));
  connect(hold, direct.hold) annotation (Line(points = {{-120, 60}, {-80, 60}, {-80, 80}, {-6, 80}, {-6, 72}}, color = {0, 0, 127}));
  connect(hold, reverse.hold) annotation (Line(points = {{-120, 60}, {-80, 60}, {-80, 20}, {-6, 20}, {-6, 12}}, color = {0, 0, 127}));
  connect(hold, comp.hold) annotation (Line(points = {{-120, 60}, {-80, 60}, {-80, -40}, {-6, -40}, {-6, -48}}, color = {0, 0, 127}));
  connect(direct.y, yDirect) annotation (Line(points = {{11, 60}, {110, 60}}, color = {0, 0, 127}));
  connect(reverse.y, yReverse) annotation (Line(points = {{11, 0}, {110, 0}}, color = {0, 0, 127}));
  connect(comp.y, m) annotation (Line(points = {{11, -60}, {110, -60}}, color = {0, 0, 127}));
  annotation (experiment(StopTime = 600, Tolerance = 1e-8), Documentation(info = "<html>
<p>Two parameter controllers (bounds 800..1200, span 2, <code>kp</code> = 0.5,
<code>Ti</code> = 60 s, <code>Te</code> = 1 s), one direct and one reverse
acting, and a state compensation (<code>k</code> = 5, <code>Te</code> = 1 s),
all driven by the top-level inputs. <code>tests/test_controllers.py</code> sets
the inputs once per 10 s sample from a recorded error sequence (hold,
saturation at both bounds, resumption) and compares the outputs with the
Python controllers step by step.</p>
</html>"));
end ParameterControllerInputs;
