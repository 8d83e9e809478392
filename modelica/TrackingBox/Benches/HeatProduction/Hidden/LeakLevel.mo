within TrackingBox.Benches.HeatProduction.Hidden;
model LeakLevel "Heat-production plant with a leak at the bottom of the storage tank T200"
  extends TrackingBox.Benches.HeatProduction.Plant(T200(use_leak=true));
  parameter TrackingBox.Units.MassFlowRate cLeak = 0.0045 "Leak flow at the reference level";
  parameter TrackingBox.Units.Height levelRef = 1.0 "Reference level of cLeak";
  TrackingBox.Interfaces.RealOutput mLeak_flow(unit="kg/s") "Leak flow out of T200"
    annotation (Placement(transformation(origin={0,110}, extent={{-10,-10},{10,10}}, rotation=90)));
equation
  mLeak_flow = cLeak*sqrt(noEvent(max(T200.level, 1e-6))/levelRef);
  connect(mLeak_flow, T200.m_flow_leak_in);
  annotation (Documentation(info="<html>
<p>A hole at the bottom of T200: the outflow grows with the square root of the
level (Torricelli), <code>cLeak&middot;sqrt(level/levelRef)</code>, 4.0 g/s at the 0.8 m
setpoint (6 % of the circulating flow). Present from the start: the level
controller LIC200 makes up for it with PU100.</p>
</html>"));
end LeakLevel;
