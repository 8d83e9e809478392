within TrackingBox.Fluid.Validation;
model DiagnosisHooks "Tank, heating unit and heat exchanger with their diagnosis hooks switched on"
  extends TrackingBox.Icons.Example;
  parameter TrackingBox.Units.MassFlowRate mLeak_flow = 0.01 "Leak flow out of the tank";
  parameter TrackingBox.Units.HeatFlowRate QLoss = 2000 "Heat loss of each component";
  TrackingBox.Fluid.OpenTank tank(nPorts_a=1, A=0.2, zInlet=1.5, level_start=0.8, T_start=323.15,
    use_leak=true, use_heatLoss=true) "Open tank with a leak and an extra heat loss";
  TrackingBox.Fluid.Sources.MassFlowSource inflow(m_flow=0.05, T=323.15) "Inflow into the tank";
  TrackingBox.Fluid.Sources.MassFlowSink outflow(m_flow=0.05) "Outflow from the tank";
  TrackingBox.Fluid.HeatingUnit heater(kht=1050, A=0.15, V=0.02, T_start=333.15, use_THeat_in=false,
    THeatFixed=413.15, use_heatLoss=true, use_kht_in=true) "Heating unit with a heat loss and kht from outside";
  TrackingBox.Fluid.HeatExchanger hex(n=5, kht=1000, A=0.45, V1=0.005, V2=0.005, T1_start=333.15,
    T2_start=313.15, use_heatLoss=true) "Heat exchanger with a heat loss of its hot side";
  TrackingBox.Fluid.Sources.MassFlowSource hotIn(m_flow=0.08, T=333.15) "Stream through heater and exchanger";
  TrackingBox.Fluid.Sources.PressureSink hotOut "Hot stream sink";
  TrackingBox.Fluid.Sources.MassFlowSource coldIn(m_flow=0.07, T=313.15) "Cold stream";
  TrackingBox.Fluid.Sources.PressureSink coldOut "Cold stream sink";
  TrackingBox.Interfaces.RealOutput leak(unit="kg/s") "Leak flow signal"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
  TrackingBox.Interfaces.RealOutput loss(unit="W") "Heat-loss signal"
    annotation (Placement(transformation(extent={{100,-10},{120,10}})));
  TrackingBox.Interfaces.RealOutput kht(unit="W/(m2.K)") "Heat-transfer coefficient of the heater, falling with time"
    annotation (Placement(transformation(extent={{100,-70},{120,-50}})));
equation
  leak = mLeak_flow;
  loss = QLoss;
  kht = 1050*(1 - 1e-4*time);
  connect(leak, tank.m_flow_leak_in);
  connect(loss, tank.Q_flow_loss_in);
  connect(loss, heater.Q_flow_loss_in);
  connect(loss, hex.Q_flow_loss_in);
  connect(kht, heater.kht_in);
  connect(inflow.port, tank.port_a[1]);
  connect(tank.port_b, outflow.port);
  connect(hotIn.port, heater.port_a);
  connect(heater.port_b, hex.port_a1);
  connect(hex.port_b1, hotOut.port);
  connect(coldIn.port, hex.port_a2);
  connect(hex.port_b2, coldOut.port);
  annotation (experiment(StopTime=1800, Tolerance=1e-6), Documentation(info="<html>
<p>Every hook of the diagnosis effects switched on: the tank loses
<code>mLeak_flow</code> (its level falls at <code>mLeak_flow/(&rho;A)</code>, the
in- and outflow being equal) and <code>QLoss</code>; the heating unit and the
exchanger's hot side lose <code>QLoss</code>; the heating unit's coefficient
comes from the input <code>kht_in</code>.</p>
</html>"));
end DiagnosisHooks;
