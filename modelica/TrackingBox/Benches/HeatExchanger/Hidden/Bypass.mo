within TrackingBox.Benches.HeatExchanger.Hidden;
model Bypass "Heat-exchanger plant with a leaking bypass valve on the hot side (outside the effect library)"
  parameter TrackingBox.Units.Fraction f = 0.1 "Fraction of the hot flow that bypasses the exchanger";
  TrackingBox.Interfaces.RealInput ThIn(unit="K", start=363.15) "Hot inlet temperature"
    annotation (Placement(transformation(extent={{-132,44},{-100,76}})));
  TrackingBox.Interfaces.RealInput TcIn(unit="K", start=283.15) "Cold inlet temperature"
    annotation (Placement(transformation(extent={{-132,-36},{-100,-4}})));
  TrackingBox.Interfaces.RealInput mHot_flow(unit="kg/s", start=1.0) "Hot mass flow rate"
    annotation (Placement(transformation(extent={{-132,4},{-100,36}})));
  TrackingBox.Interfaces.RealInput mCold_flow(unit="kg/s", start=2.0) "Cold mass flow rate"
    annotation (Placement(transformation(extent={{-132,-76},{-100,-44}})));
  TrackingBox.Interfaces.RealOutput ThOut(unit="K") "Hot outlet temperature, after the bypass joins"
    annotation (Placement(transformation(extent={{100,20},{120,40}})));
  TrackingBox.Interfaces.RealOutput TcOut(unit="K") "Cold outlet temperature"
    annotation (Placement(transformation(extent={{100,-40},{120,-20}})));
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
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-100,100},{100,-100}}, lineColor={0,0,0}, fillColor={245,245,245}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-60,50},{60,10}}, lineColor={0,0,0}, fillColor={255,170,170}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-60,-10},{60,-50}}, lineColor={0,0,0}, fillColor={170,213,255}, fillPattern=FillPattern.Solid),
      Line(points={{-80,30},{80,30}}, color={238,46,47}, thickness=0.5, arrow={Arrow.None, Arrow.Filled}),
      Line(points={{80,-30},{-80,-30}}, color={0,127,255}, thickness=0.5, arrow={Arrow.None, Arrow.Filled}),
      Line(points={{-80,30},{-80,70},{80,70},{80,30}}, color={238,46,47}, pattern=LinePattern.Dash),
      Text(extent={{-150,145},{150,105}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>The plant (<code>kht</code> = 910) with a fraction <code>f</code> of the hot
stream passing a leaking bypass valve: the exchanger sees <code>(1 -
f)&middot;mHot_flow</code> and the bypassed water joins the hot outlet before
TI-102 (adiabatic mixing). No entry of the effect library describes it.</p>
</html>"));
end Bypass;
