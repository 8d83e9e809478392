within TrackingBox.Benches.HeatExchanger.Hidden;
model Bypass "Heat-exchanger plant with a leaking bypass valve on the hot side (outside the effect library)"
  parameter TrackingBox.Units.Fraction f = 0.1 "Fraction of the hot flow that bypasses the exchanger";
  TrackingBox.Interfaces.RealInput ThIn(unit="K", start=363.15) "Hot inlet temperature";
  TrackingBox.Interfaces.RealInput TcIn(unit="K", start=283.15) "Cold inlet temperature";
  TrackingBox.Interfaces.RealInput mHot_flow(unit="kg/s", start=1.0) "Hot mass flow rate";
  TrackingBox.Interfaces.RealInput mCold_flow(unit="kg/s", start=2.0) "Cold mass flow rate";
  TrackingBox.Interfaces.RealOutput ThOut(unit="K") "Hot outlet temperature, after the bypass joins";
  TrackingBox.Interfaces.RealOutput TcOut(unit="K") "Cold outlet temperature";
  TrackingBox.Fluid.HeatExchanger hx(n=10, kht=910, A=4.2, V1=0.12, V2=0.12, T1_start=333.15, T2_start=308.15)
    "Counter-flow heat exchanger (side 1 hot, side 2 cold)";
  TrackingBox.Fluid.Sources.MassFlowSource hotIn(use_m_flow_in=true, use_T_in=true) "Hot stream through the exchanger";
  TrackingBox.Fluid.Sources.MassFlowSource coldIn(use_m_flow_in=true, use_T_in=true) "Cold stream source";
  TrackingBox.Fluid.Sources.PressureSink hotOut "Hot stream sink";
  TrackingBox.Fluid.Sources.PressureSink coldOut "Cold stream sink";
equation
  hotIn.m_flow_in = (1 - f)*mHot_flow;
  connect(ThIn, hotIn.T_in);
  connect(mCold_flow, coldIn.m_flow_in);
  connect(TcIn, coldIn.T_in);
  connect(hotIn.port, hx.port_a1);
  connect(hx.port_b1, hotOut.port);
  connect(coldIn.port, hx.port_a2);
  connect(hx.port_b2, coldOut.port);
  ThOut = (1 - f)*hx.port_b1.T + f*ThIn;
  TcOut = hx.port_b2.T;
  annotation (Documentation(info="<html>
<p>The plant (<code>kht</code> = 910) with a fraction <code>f</code> of the hot
stream passing a leaking bypass valve: the exchanger sees <code>(1 -
f)&middot;mHot_flow</code> and the bypassed water joins the hot outlet before
TI-102 (adiabatic mixing). No entry of the effect library describes it.</p>
</html>"));
end Bypass;
