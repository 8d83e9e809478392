within TrackingBox.Fluid;
model HeatExchanger "Counter-flow water/water heat exchanger with n cells per side"
  parameter Integer n(min=1) = 10 "Number of cells per side";
  parameter TrackingBox.Units.CoefficientOfHeatTransfer kht = 1000 "Heat-transfer coefficient";
  parameter TrackingBox.Units.Area A = 4 "Heat-transfer area";
  parameter TrackingBox.Units.Volume V1 = 0.1 "Water volume of side 1 (hot)";
  parameter TrackingBox.Units.Volume V2 = 0.1 "Water volume of side 2 (cold)";
  parameter TrackingBox.Units.PressureDifference dp1_nominal = 0 "Pressure loss of side 1 at m1_flow_nominal (linear law)";
  parameter TrackingBox.Units.PressureDifference dp2_nominal = 0 "Pressure loss of side 2 at m2_flow_nominal (linear law)";
  parameter TrackingBox.Units.MassFlowRate m1_flow_nominal = 1 "Nominal mass flow rate of side 1";
  parameter TrackingBox.Units.MassFlowRate m2_flow_nominal = 1 "Nominal mass flow rate of side 2";
  parameter TrackingBox.Units.Temperature T1_start = 333.15 "Initial temperature of side 1";
  parameter TrackingBox.Units.Temperature T2_start = 303.15 "Initial temperature of side 2";
  parameter Boolean use_kht_in = false "= true to take kht from the input kht_in";
  parameter Boolean use_heatLoss = false "= true for a heat loss Q_flow_loss_in from side 1 to the surroundings";
  TrackingBox.Interfaces.FluidPort_a port_a1 "Side 1 (hot) inlet"
    annotation (Placement(transformation(extent={{-110,50},{-90,70}})));
  TrackingBox.Interfaces.FluidPort_b port_b1 "Side 1 (hot) outlet"
    annotation (Placement(transformation(extent={{90,50},{110,70}})));
  TrackingBox.Interfaces.FluidPort_a port_a2 "Side 2 (cold) inlet"
    annotation (Placement(transformation(extent={{90,-70},{110,-50}})));
  TrackingBox.Interfaces.FluidPort_b port_b2 "Side 2 (cold) outlet"
    annotation (Placement(transformation(extent={{-110,-70},{-90,-50}})));
  TrackingBox.Interfaces.RealInput kht_in(unit="W/(m2.K)") if use_kht_in "Heat-transfer coefficient from outside"
    annotation (Placement(transformation(origin={0,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput Q_flow_loss_in(unit="W") if use_heatLoss "Heat flow lost from side 1 to the surroundings, shared evenly by its cells"
    annotation (Placement(transformation(origin={60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Units.Temperature T1[n](each start=T1_start, each fixed=true) "Side 1 cell temperatures, in flow order";
  TrackingBox.Units.Temperature T2[n](each start=T2_start, each fixed=true) "Side 2 cell temperatures; cell i faces T1[i], flow from n to 1";
  TrackingBox.Units.HeatFlowRate Q_flow[n] "Heat flow from side 1 to side 2 per cell";
  TrackingBox.Units.HeatFlowRate Q_total "Total heat flow from side 1 to side 2";
  TrackingBox.Units.MassFlowRate m1_flow "Side 1 mass flow rate";
  TrackingBox.Units.MassFlowRate m2_flow "Side 2 mass flow rate";
protected
  TrackingBox.Interfaces.RealInput kht_internal(unit="W/(m2.K)") "Used heat-transfer coefficient";
  TrackingBox.Interfaces.RealInput Q_flow_loss_internal(unit="W") "Heat loss of side 1 (0 without it)";
  TrackingBox.Units.Temperature T1_in[n] "Inlet temperature of each side-1 cell";
  TrackingBox.Units.Temperature T2_in[n] "Inlet temperature of each side-2 cell";
equation
  connect(kht_in, kht_internal);
  connect(Q_flow_loss_in, Q_flow_loss_internal);
  if not use_kht_in then
    kht_internal = kht;
  end if;
  if not use_heatLoss then
    Q_flow_loss_internal = 0;
  end if;
  port_a1.m_flow + port_b1.m_flow = 0;
  port_a2.m_flow + port_b2.m_flow = 0;
  m1_flow = port_a1.m_flow;
  m2_flow = port_a2.m_flow;
  port_a1.p - port_b1.p = dp1_nominal*m1_flow/m1_flow_nominal;
  port_a2.p - port_b2.p = dp2_nominal*m2_flow/m2_flow_nominal;
  T1_in[1] = port_a1.T;
  T2_in[n] = port_a2.T;
  for i in 2:n loop
    T1_in[i] = T1[i - 1];
  end for;
  for i in 1:n - 1 loop
    T2_in[i] = T2[i + 1];
  end for;
  for i in 1:n loop
    Q_flow[i] = kht_internal*A/n*(T1[i] - T2[i]);
    TrackingBox.Media.Water.rho(T1[i])*V1/n*der(T1[i]) = noEvent(max(m1_flow, 0))*(T1_in[i] - T1[i]) - (Q_flow[i] + Q_flow_loss_internal/n)/TrackingBox.Media.Water.cp(T1[i]);
    TrackingBox.Media.Water.rho(T2[i])*V2/n*der(T2[i]) = noEvent(max(m2_flow, 0))*(T2_in[i] - T2[i]) + Q_flow[i]/TrackingBox.Media.Water.cp(T2[i]);
  end for;
  Q_total = sum(Q_flow);
  port_b1.T = T1[n];
  port_b2.T = T2[1];
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-90,90},{90,-90}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-90,90},{90,30}}, lineColor={0,0,0}, fillColor={255,170,170}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-90,-30},{90,-90}}, lineColor={0,0,0}, fillColor={170,213,255}, fillPattern=FillPattern.Solid),
      Line(points={{-90,60},{90,60}}, color={238,46,47}, thickness=0.5, arrow={Arrow.None, Arrow.Filled}),
      Line(points={{90,-60},{-90,-60}}, color={0,127,255}, thickness=0.5, arrow={Arrow.None, Arrow.Filled}),
      Line(points={{-40,25},{-40,-25}}, color={238,46,47}, arrow={Arrow.None, Arrow.Filled}),
      Line(points={{0,25},{0,-25}}, color={238,46,47}, arrow={Arrow.None, Arrow.Filled}),
      Line(points={{40,25},{40,-25}}, color={238,46,47}, arrow={Arrow.None, Arrow.Filled}),
      Text(extent={{-150,-100},{150,-140}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Each side is a chain of <code>n</code> well-mixed cells (upwind in the
design flow direction); cell <code>i</code> of side 1 exchanges
<code>kht&middot;A/n&middot;(T1[i] - T2[i])</code> with cell <code>i</code> of side 2.
Side 1 flows from cell 1 to n, side 2 from n to 1 (counter-flow). Wall heat
capacity is neglected. Optional linear pressure loss per side.</p>
<p>The upwind cell chain slightly underestimates the effectiveness of an
ideal counter-flow exchanger: with <code>n = 10</code> and NTU = 1 the hot outlet
is about 1.8 K warmer than the analytic &epsilon;-NTU value (80 K span).</p>
<p>Hooks for diagnosis (off by default): <code>use_kht_in</code> takes the
coefficient from the input <code>kht_in</code>; <code>use_heatLoss</code>
takes a heat flow <code>Q_flow_loss_in</code> (W) that side 1 loses to the
surroundings, each cell losing <code>Q_flow_loss_in/n</code>.</p>
</html>"));
end HeatExchanger;
