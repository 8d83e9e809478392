within TrackingBox.Benches.HeatProduction.BaseClasses;
partial model PartialProcess "Heat-production process: components, controllers, inputs and sensor outputs"
  parameter Boolean quadratic = false "= true: quadratic pipe and pump curves (plant); false: linear (twin): pipes proportional to the flow, pumps the chord from shut-off to the design point";
  parameter TrackingBox.Units.Height level100Set = 0.8 "Level setpoint of T100";
  parameter TrackingBox.Units.Height level200Set = 0.8 "Level setpoint of T200";
  parameter TrackingBox.Units.Height level400Set = 0.6 "Level setpoint of T400";
  parameter TrackingBox.Units.MassFlowRate mBleed_flow = 0.02 "Bleed (excess water) drawn from the bottom of T100";
  parameter TrackingBox.Units.MassFlowRate mMakeUpMax_flow = 0.06 "Make-up flow into T400 at full LIC400 output";
  parameter TrackingBox.Units.Power QPreMax = 20000 "Preheater power in T100 at full TIC100 output";
  parameter TrackingBox.Units.Temperature THeatMin = 373.15 "Heating-medium temperature of HU300 at TIC300 output 0";
  parameter TrackingBox.Units.Temperature THeatMax = 443.15 "Heating-medium temperature of HU300 at TIC300 output 1";
  // Inputs
  TrackingBox.Interfaces.RealInput mCold_flow(unit="kg/s", start=0.07) "Heat demand: mass flow of the external cold stream"
    annotation (Placement(transformation(extent={{-118,75},{-100,93}})));
  TrackingBox.Interfaces.RealInput TColdIn(unit="K", start=313.15) "Heat demand: inlet temperature of the cold stream"
    annotation (Placement(transformation(extent={{-118,51},{-100,69}})));
  TrackingBox.Interfaces.RealInput TColdOut_set(unit="K", start=338.15) "Setpoint of the cold-stream outlet temperature (TIC302)"
    annotation (Placement(transformation(extent={{-118,27},{-100,45}})));
  TrackingBox.Interfaces.RealInput THU300_set(unit="K", start=363.15) "Setpoint of the HU300 outlet temperature (TIC300)"
    annotation (Placement(transformation(extent={{-118,3},{-100,21}})));
  TrackingBox.Interfaces.RealInput TPre_set(unit="K", start=328.15) "Setpoint of the T100 temperature (TIC100)"
    annotation (Placement(transformation(extent={{-118,-21},{-100,-3}})));
  TrackingBox.Interfaces.RealInput TMakeUp(unit="K", start=288.15) "Make-up water temperature"
    annotation (Placement(transformation(extent={{-118,-45},{-100,-27}})));
  TrackingBox.Interfaces.RealInput TAmb(unit="K", start=293.15) "Ambient temperature (tank heat losses)"
    annotation (Placement(transformation(extent={{-118,-69},{-100,-51}})));
  TrackingBox.Interfaces.RealInput holdControllers(unit="1", start=0) "> 0.5 freezes all PI controllers (outputs held)"
    annotation (Placement(transformation(extent={{-118,-93},{-100,-75}})));
  // Sensor outputs
  TrackingBox.Interfaces.RealOutput LI_100(unit="m") "Level T100"
    annotation (Placement(transformation(extent={{100,77},{106,83}})));
  TrackingBox.Interfaces.RealOutput LI_200(unit="m") "Level T200"
    annotation (Placement(transformation(extent={{100,69},{106,75}})));
  TrackingBox.Interfaces.RealOutput LI_400(unit="m") "Level T400"
    annotation (Placement(transformation(extent={{100,61},{106,67}})));
  TrackingBox.Interfaces.RealOutput TI_100(unit="K") "Temperature T100"
    annotation (Placement(transformation(extent={{100,53},{106,59}})));
  TrackingBox.Interfaces.RealOutput TI_200(unit="K") "Temperature T200"
    annotation (Placement(transformation(extent={{100,45},{106,51}})));
  TrackingBox.Interfaces.RealOutput TI_300(unit="K") "Temperature HU300 outlet"
    annotation (Placement(transformation(extent={{100,37},{106,43}})));
  TrackingBox.Interfaces.RealOutput TI_301(unit="K") "Temperature HEX300 hot-side outlet"
    annotation (Placement(transformation(extent={{100,29},{106,35}})));
  TrackingBox.Interfaces.RealOutput TI_302(unit="K") "Temperature cold-stream outlet"
    annotation (Placement(transformation(extent={{100,21},{106,27}})));
  TrackingBox.Interfaces.RealOutput TI_310(unit="K") "Temperature of the HU300 heating medium"
    annotation (Placement(transformation(extent={{100,13},{106,19}})));
  TrackingBox.Interfaces.RealOutput TI_400(unit="K") "Temperature T400"
    annotation (Placement(transformation(extent={{100,5},{106,11}})));
  TrackingBox.Interfaces.RealOutput FI_100(unit="kg/s") "Flow PU100 (T100 to T200)"
    annotation (Placement(transformation(extent={{100,-3},{106,3}})));
  TrackingBox.Interfaces.RealOutput FI_101(unit="kg/s") "Flow V400 (T400 to T100)"
    annotation (Placement(transformation(extent={{100,-11},{106,-5}})));
  TrackingBox.Interfaces.RealOutput FI_200(unit="kg/s") "Flow PU200 (through HU300 and HEX300)"
    annotation (Placement(transformation(extent={{100,-19},{106,-13}})));
  TrackingBox.Interfaces.RealOutput FI_400(unit="kg/s") "Make-up flow into T400"
    annotation (Placement(transformation(extent={{100,-27},{106,-21}})));
  TrackingBox.Interfaces.RealOutput PI_100(unit="Pa") "Pressure at the PU100 discharge"
    annotation (Placement(transformation(extent={{100,-35},{106,-29}})));
  TrackingBox.Interfaces.RealOutput PI_200(unit="Pa") "Pressure at the PU200 discharge"
    annotation (Placement(transformation(extent={{100,-43},{106,-37}})));
  TrackingBox.Interfaces.RealOutput PI_300(unit="Pa") "Pressure in HU300"
    annotation (Placement(transformation(extent={{100,-51},{106,-45}})));
  TrackingBox.Interfaces.RealOutput SI_100(unit="1") "Relative speed PU100"
    annotation (Placement(transformation(extent={{100,-59},{106,-53}})));
  TrackingBox.Interfaces.RealOutput SI_200(unit="1") "Relative speed PU200"
    annotation (Placement(transformation(extent={{100,-67},{106,-61}})));
  TrackingBox.Interfaces.RealOutput ZI_400(unit="1") "Opening V400"
    annotation (Placement(transformation(extent={{100,-75},{106,-69}})));
  TrackingBox.Interfaces.RealOutput QI_100(unit="W") "Preheater power T100"
    annotation (Placement(transformation(extent={{100,-83},{106,-77}})));
  // Tanks
  TrackingBox.Fluid.OpenTank T100(nPorts_a=2, A=0.3, zBottom=0, zInlet=1.2, level_start=0.8, T_start=328.15,
    UA=5, use_Q_flow_in=true, use_TAmb_in=true) "Preheating tank";
  TrackingBox.Fluid.OpenTank T200(nPorts_a=1, A=0.3, zBottom=0, zInlet=1.5, level_start=0.8, T_start=328.15,
    UA=5, use_TAmb_in=true) "Storage tank";
  TrackingBox.Fluid.OpenTank T400(nPorts_a=1, A=0.3, zBottom=2.0, zInlet=3.2, level_start=0.6, T_start=288.15,
    UA=5, use_TAmb_in=true) "Elevated make-up tank";
  // Line T100 -> T200
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedTransferPump PU100(quadratic=quadratic, VFlowDesign=6.6e-5, uRise=40000) "Pump T100 to T200";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedPipe Pipe100(quadratic=quadratic, k=0.005, m_flow_nominal=0.05) "Pipe T100 to T200";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedValve V100(KvMax=1.0, use_opening_in=false, openingFixed=1.0) "Hand valve T100 to T200";
  // Line T200 -> HU300 -> HEX300 -> T100
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedCirculationPump PU200(quadratic=quadratic, VFlowDesign=8.3e-5, uRise=40000) "Pump T200 to HU300";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedPipe Pipe200(quadratic=quadratic, k=0.005, m_flow_nominal=0.05) "Pipe T200 to HU300";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedValve V200(KvMax=1.0, use_opening_in=false, openingFixed=1.0) "Hand valve before HU300";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedHeatingUnit HU300(kht=1050, A=0.2, V=0.03, T_start=363.15) "Pressurised heating unit";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedHeatExchanger HEX300(n=5, kht=1000, A=0.6, V1=0.008, V2=0.008,
    T1_start=348.15, T2_start=328.15) "Heat exchanger to the external cold stream (side 1 hot, side 2 cold)";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedPipe Pipe201(quadratic=quadratic, k=0.005, m_flow_nominal=0.05) "Return pipe HEX300 to T100";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedValve V300(KvMax=1.0, use_opening_in=false, openingFixed=1.0) "Hand valve in the return";
  // Make-up line T400 -> T100
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedPipe Pipe101(quadratic=quadratic, k=0.005, m_flow_nominal=0.02) "Pipe T400 to T100";
  TrackingBox.Benches.HeatProduction.BaseClasses.TrackedValve V400(KvMax=1.0) "Control valve T400 to T100 (LIC100)";
  // Boundaries
  TrackingBox.Fluid.Sources.MassFlowSource makeUp(use_m_flow_in=true, use_T_in=true) "Make-up water into T400";
  TrackingBox.Fluid.Sources.MassFlowSink bleed(m_flow=mBleed_flow) "Bleed of excess water from T100";
  TrackingBox.Fluid.Sources.MassFlowSource coldIn(use_m_flow_in=true, use_T_in=true) "External cold stream (heat demand)";
  TrackingBox.Fluid.Sources.PressureSink coldOut "External cold stream return";
  // Controllers
  TrackingBox.Blocks.PI LIC100(k=10, Ti=1200, Tt=60, Tf=2, yMin=0, yMax=1, y_start=0.25) "Level T100 by V400";
  TrackingBox.Blocks.PI LIC200(k=5, Ti=1200, Tt=60, Tf=2, yMin=0.2, yMax=1, y_start=0.8) "Level T200 by PU100 speed";
  TrackingBox.Blocks.PI LIC400(k=15, Ti=1200, Tt=60, Tf=2, yMin=0, yMax=1, y_start=0.35) "Level T400 by make-up flow";
  TrackingBox.Blocks.PI TIC100(k=0.1, Ti=1200, Tt=60, Tf=2, yMin=0, yMax=1, y_start=0.25) "Temperature T100 by preheater power";
  TrackingBox.Blocks.PI TIC300(k=0.05, Ti=300, Tt=60, Tf=2, yMin=0, yMax=1, y_start=0.5) "HU300 outlet temperature by heating-medium temperature";
  TrackingBox.Blocks.PI TIC302(k=0.03, Ti=150, Tt=60, Tf=2, yMin=0.2, yMax=1, y_start=0.75) "Cold-stream outlet temperature by PU200 speed";
equation
  // Water circuit
  connect(T100.port_b, PU100.port_a);
  connect(T100.port_b, bleed.port);
  connect(PU100.port_b, Pipe100.port_a);
  connect(Pipe100.port_b, V100.port_a);
  connect(V100.port_b, T200.port_a[1]);
  connect(T200.port_b, PU200.port_a);
  connect(PU200.port_b, Pipe200.port_a);
  connect(Pipe200.port_b, V200.port_a);
  connect(V200.port_b, HU300.port_a);
  connect(HU300.port_b, HEX300.port_a1);
  connect(HEX300.port_b1, Pipe201.port_a);
  connect(Pipe201.port_b, V300.port_a);
  connect(V300.port_b, T100.port_a[1]);
  connect(makeUp.port, T400.port_a[1]);
  connect(T400.port_b, Pipe101.port_a);
  connect(Pipe101.port_b, V400.port_a);
  connect(V400.port_b, T100.port_a[2]);
  connect(coldIn.port, HEX300.port_a2);
  connect(HEX300.port_b2, coldOut.port);
  // Boundary inputs
  connect(mCold_flow, coldIn.m_flow_in);
  connect(TColdIn, coldIn.T_in);
  connect(TMakeUp, makeUp.T_in);
  connect(TAmb, T100.TAmb_in);
  connect(TAmb, T200.TAmb_in);
  connect(TAmb, T400.TAmb_in);
  // Controllers
  connect(holdControllers, LIC100.hold);
  connect(holdControllers, LIC200.hold);
  connect(holdControllers, LIC400.hold);
  connect(holdControllers, TIC100.hold);
  connect(holdControllers, TIC300.hold);
  connect(holdControllers, TIC302.hold);
  LIC100.u_s = level100Set;
  LIC100.u_m = T100.level;
  connect(LIC100.y, V400.opening);
  LIC200.u_s = level200Set;
  LIC200.u_m = T200.level;
  connect(LIC200.y, PU100.speed);
  LIC400.u_s = level400Set;
  LIC400.u_m = T400.level;
  makeUp.m_flow_in = mMakeUpMax_flow*LIC400.y;
  connect(TPre_set, TIC100.u_s);
  TIC100.u_m = T100.T;
  T100.Q_flow_in = QPreMax*TIC100.y;
  connect(THU300_set, TIC300.u_s);
  TIC300.u_m = HU300.T;
  HU300.THeat = THeatMin + (THeatMax - THeatMin)*TIC300.y;
  connect(TColdOut_set, TIC302.u_s);
  TIC302.u_m = HEX300.port_b2.T;
  connect(TIC302.y, PU200.speed);
  // Sensors
  LI_100 = T100.level;
  LI_200 = T200.level;
  LI_400 = T400.level;
  TI_100 = T100.T;
  TI_200 = T200.T;
  TI_300 = HU300.T;
  TI_301 = HEX300.port_b1.T;
  TI_302 = HEX300.port_b2.T;
  TI_310 = HU300.THeat;
  TI_400 = T400.T;
  FI_100 = PU100.m_flow;
  FI_101 = V400.m_flow;
  FI_200 = PU200.m_flow;
  FI_400 = makeUp.m_flow_in;
  PI_100 = PU100.port_b.p;
  PI_200 = PU200.port_b.p;
  PI_300 = HU300.port_a.p;
  SI_100 = PU100.speed;
  SI_200 = PU200.speed;
  ZI_400 = V400.opening;
  QI_100 = T100.Q_flow_in;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-100,100},{100,-100}}, lineColor={0,0,0}, fillColor={245,245,245}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-70,60},{-40,10}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-15,60},{15,10}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{40,40},{70,-10}}, lineColor={0,0,0}, fillColor={238,46,47}, fillPattern=FillPattern.Solid),
      Line(points={{-55,10},{-55,-30},{55,-30},{55,-10}}, color={0,127,255}, thickness=0.5),
      Line(points={{-40,35},{-15,35}}, color={0,127,255}, thickness=0.5),
      Line(points={{15,35},{40,35}}, color={0,127,255}, thickness=0.5),
      Text(extent={{-150,145},{150,105}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Structure shared by <code>Plant</code> and <code>Twin</code>, with the
twin's parameter values (the method notes' initial values). <code>Twin</code>
extends it; <code>Plant</code> overrides values with plain modifiers. The
tracking bounds of the trackable parameters come with the components'
classes (<code>TrackedHeatingUnit</code>, <code>TrackedHeatExchanger</code>,
<code>TrackedPipe</code>, <code>TrackedValve</code>,
<code>TrackedTransferPump</code>, <code>TrackedCirculationPump</code>), so
plant and twin both keep them.</p>
<p>Pressures are absolute and piezometric (reference: bottom of T100/T200).
All controllers share the hold input <code>holdControllers</code>.</p>
</html>"));
end PartialProcess;
