within TrackingBox.Fluid;
model HeatingUnit "Liquid-full (pressurised) heating vessel, heated through a surface by a heating medium"
  extends TrackingBox.Interfaces.PartialTwoPort;
  parameter TrackingBox.Units.CoefficientOfHeatTransfer kht = 1050 "Heat-transfer coefficient heating medium to water";
  parameter TrackingBox.Units.Area A = 0.15 "Heat-transfer area";
  parameter TrackingBox.Units.Volume V = 0.02 "Water volume";
  parameter TrackingBox.Units.Temperature T_start = 353.15 "Initial water temperature";
  parameter TrackingBox.Units.Temperature THeatFixed = 413.15 "Heating-medium temperature used when use_THeat_in = false";
  parameter Boolean use_kht_in = false "= true to take kht from the input kht_in";
  parameter Boolean use_THeat_in = true "= true to take the heating-medium temperature from the input THeat";
  parameter Boolean use_heatLoss = false "= true for a heat loss Q_flow_loss_in from the water to the surroundings";
  TrackingBox.Interfaces.RealInput kht_in(unit="W/(m2.K)") if use_kht_in "Heat-transfer coefficient from outside"
    annotation (Placement(transformation(origin={-60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput THeat(unit="K") if use_THeat_in "Heating-medium temperature (e.g. saturated steam)"
    annotation (Placement(transformation(origin={0,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput Q_flow_loss_in(unit="W") if use_heatLoss "Heat flow lost from the water to the surroundings"
    annotation (Placement(transformation(origin={60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Units.Temperature T(start=T_start, fixed=true) "Water temperature (well mixed)";
  TrackingBox.Units.HeatFlowRate Q_flow "Heat flow into the water";
protected
  TrackingBox.Interfaces.RealInput kht_internal(unit="W/(m2.K)") "Used heat-transfer coefficient";
  TrackingBox.Interfaces.RealInput THeat_internal(unit="K") "Used heating-medium temperature";
  TrackingBox.Interfaces.RealInput Q_flow_loss_internal(unit="W") "Heat loss (0 without it)";
equation
  connect(kht_in, kht_internal);
  connect(THeat, THeat_internal);
  connect(Q_flow_loss_in, Q_flow_loss_internal);
  if not use_kht_in then
    kht_internal = kht;
  end if;
  if not use_THeat_in then
    THeat_internal = THeatFixed;
  end if;
  if not use_heatLoss then
    Q_flow_loss_internal = 0;
  end if;
  dp = 0;
  Q_flow = kht_internal*A*(THeat_internal - T);
  TrackingBox.Media.Water.rho(T)*V*der(T) = noEvent(max(m_flow, 0))*(port_a.T - T) + (Q_flow - Q_flow_loss_internal)/TrackingBox.Media.Water.cp(T);
  port_b.T = T;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-80,60},{80,-60}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.Solid),
      Line(points={{-60,-40},{-40,40},{-20,-40},{0,40},{20,-40},{40,40},{60,-40}}, color={238,46,47}, thickness=0.5),
      Line(points={{0,60},{0,100}}, color={0,0,127}),
      Text(extent={{-150,-70},{150,-110}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Well-mixed water volume <code>V</code> without pressure loss, heated with
<code>Q = kht&middot;A&middot;(THeat - T)</code> from a heating medium at
<code>THeat</code>. Being liquid-full, the pressure is set by the network.</p>
<p>Hooks for diagnosis (off by default): <code>use_kht_in</code> takes the
coefficient from the input <code>kht_in</code>; <code>use_heatLoss</code>
subtracts the heat flow <code>Q_flow_loss_in</code> (W) lost to the
surroundings from the water's energy balance.</p>
</html>"));
end HeatingUnit;
