within TrackingBox.Benches.Evaporator.BaseClasses;
partial model PartialSlice "Last-effect slice: inlet flow loop, effect with level loop, flash tank, pump, condensate tank"
  parameter TrackingBox.Units.Pressure feedSourceP = 3.5e5 "Pressure of the liquor source ahead of the inlet valve";
  parameter TrackingBox.Units.Pressure flashSinkP = 1.0e5 "Pressure of the header receiving the flash vapour";
  parameter TrackingBox.Units.Pressure productSinkP = 3e5 "Pressure at the end of the product line";
  parameter TrackingBox.Units.Pressure condensateSinkP = 1e5 "Pressure at the end of the condensate line";
  parameter TrackingBox.Units.Height bodyLevelSet = 1.2 "Setpoint of the effect level (as read by LI_body)";
  parameter TrackingBox.Units.Height flashLevelSet = 1.0 "Setpoint of the flash-tank level (as read by LI_flash)";
  parameter TrackingBox.Units.Height condensateLevelSet = 0.8 "Setpoint of the condensate-tank level (as read by LI_condensate)";
  parameter Real steamRatio(unit="s/kg") = 0.32 "Steam-valve opening = tanh(steamRatio*FI_feed) (ratio station)";
  TrackingBox.Interfaces.RealInput feedFlowSet(unit="kg/s", start=2) "Setpoint of the inlet flow loop"
    annotation (Placement(transformation(extent={{-114,83},{-100,97}})));
  TrackingBox.Interfaces.RealInput feedDS(unit="1", start=0.52) "Dry-solids fraction of the incoming liquor"
    annotation (Placement(transformation(extent={{-114,65},{-100,79}})));
  TrackingBox.Interfaces.RealInput feedT(unit="K", start=368.15) "Temperature of the incoming liquor"
    annotation (Placement(transformation(extent={{-114,47},{-100,61}})));
  TrackingBox.Interfaces.RealInput steamP(unit="Pa", start=4e5) "Pressure of the steam source"
    annotation (Placement(transformation(extent={{-114,29},{-100,43}})));
  TrackingBox.Interfaces.RealInput nextP(unit="Pa", start=1.4e5) "Vapour boundary pressure (steam chest of the next effect)"
    annotation (Placement(transformation(extent={{-114,11},{-100,25}})));
  TrackingBox.Interfaces.RealInput holdControllers(unit="1", start=0) "> 0.5 freezes all PI controllers (outputs held)"
    annotation (Placement(transformation(extent={{-114,-7},{-100,7}})));
  TrackingBox.Interfaces.RealInput holdFlowController(unit="1", start=0) "> 0.5 freezes the inlet flow loop FIC_feed"
    annotation (Placement(transformation(extent={{-114,-25},{-100,-11}})));
  TrackingBox.Interfaces.RealInput holdLevelControllers(unit="1", start=0) "> 0.5 freezes the three level loops"
    annotation (Placement(transformation(extent={{-114,-43},{-100,-29}})));
  TrackingBox.Interfaces.RealInput holdBodyLevelController(unit="1", start=0) "> 0.5 freezes the effect level loop LIC_body"
    annotation (Placement(transformation(extent={{-114,-61},{-100,-47}})));
  TrackingBox.Interfaces.RealInput holdFlashLevelController(unit="1", start=0) "> 0.5 freezes the flash-tank level loop LIC_flash"
    annotation (Placement(transformation(extent={{-114,-79},{-100,-65}})));
  TrackingBox.Interfaces.RealInput holdCondensateLevelController(unit="1", start=0) "> 0.5 freezes the condensate level loop LIC_condensate"
    annotation (Placement(transformation(extent={{-114,-97},{-100,-83}})));
  TrackingBox.Interfaces.RealOutput FI_feed(unit="kg/s") "Liquor inflow"
    annotation (Placement(transformation(extent={{100,86},{108,94}})));
  TrackingBox.Interfaces.RealOutput FI_product(unit="kg/s") "Product liquor flow"
    annotation (Placement(transformation(extent={{100,76},{108,84}})));
  TrackingBox.Interfaces.RealOutput FI_condensate(unit="kg/s") "Condensate flow from the steam chest"
    annotation (Placement(transformation(extent={{100,66},{108,74}})));
  TrackingBox.Interfaces.RealOutput FI_steam(unit="kg/s") "Steam flow into the steam chest"
    annotation (Placement(transformation(extent={{100,56},{108,64}})));
  TrackingBox.Interfaces.RealOutput PI_vapour(unit="Pa") "Pressure in the effect's vapour space"
    annotation (Placement(transformation(extent={{100,46},{108,54}})));
  TrackingBox.Interfaces.RealOutput PI_flash(unit="Pa") "Pressure in the flash tank"
    annotation (Placement(transformation(extent={{100,36},{108,44}})));
  TrackingBox.Interfaces.RealOutput PI_steamChest(unit="Pa") "Pressure in the steam chest"
    annotation (Placement(transformation(extent={{100,26},{108,34}})));
  TrackingBox.Interfaces.RealOutput PI_pump(unit="Pa") "Discharge pressure of the product pump"
    annotation (Placement(transformation(extent={{100,16},{108,24}})));
  TrackingBox.Interfaces.RealOutput TI_body(unit="K") "Liquor temperature in the effect"
    annotation (Placement(transformation(extent={{100,6},{108,14}})));
  TrackingBox.Interfaces.RealOutput TI_flash(unit="K") "Liquor temperature after the flash tank"
    annotation (Placement(transformation(extent={{100,-4},{108,4}})));
  TrackingBox.Interfaces.RealOutput LI_body(unit="m") "Effect level from the dP transmitter"
    annotation (Placement(transformation(extent={{100,-14},{108,-6}})));
  TrackingBox.Interfaces.RealOutput LI_flash(unit="m") "Flash-tank level from the dP transmitter"
    annotation (Placement(transformation(extent={{100,-24},{108,-16}})));
  TrackingBox.Interfaces.RealOutput LI_condensate(unit="m") "Condensate-tank level from the dP transmitter"
    annotation (Placement(transformation(extent={{100,-34},{108,-26}})));
  TrackingBox.Interfaces.RealOutput DI_product(unit="1") "Product dry solids (DS meter)"
    annotation (Placement(transformation(extent={{100,-44},{108,-36}})));
  TrackingBox.Interfaces.RealOutput ZI_inlet(unit="1") "Inlet valve position"
    annotation (Placement(transformation(extent={{100,-54},{108,-46}})));
  TrackingBox.Interfaces.RealOutput ZI_outlet(unit="1") "Outlet valve position (effect level loop)"
    annotation (Placement(transformation(extent={{100,-64},{108,-56}})));
  TrackingBox.Interfaces.RealOutput ZI_product(unit="1") "Product valve position (flash level loop)"
    annotation (Placement(transformation(extent={{100,-74},{108,-66}})));
  TrackingBox.Interfaces.RealOutput ZI_condensate(unit="1") "Condensate valve position (condensate level loop)"
    annotation (Placement(transformation(extent={{100,-84},{108,-76}})));
  TrackingBox.Interfaces.RealOutput ZI_steam(unit="1") "Steam valve position"
    annotation (Placement(transformation(extent={{100,-94},{108,-86}})));
  TrackingBox.Evaporation.Sources.LiquorSource feedSource(p=feedSourceP, use_T_in=true, use_x_in=true) "Liquor from the previous effect";
  TrackingBox.Benches.Evaporator.BaseClasses.TrackedInletValve inletValve(KvMax=17, equalPercentage=true) "Inlet valve (flow loop)";
  TrackingBox.Evaporation.Effect effect "The last effect";
  TrackingBox.Benches.Evaporator.BaseClasses.TrackedOutletValve outletValve(KvMax=7) "Outlet valve (effect level loop)";
  TrackingBox.Evaporation.FlashTank flash "Product flash tank";
  TrackingBox.Benches.Evaporator.BaseClasses.TrackedProductPump pump(dp0=4e5, VMax=3e-3) "Product pump";
  TrackingBox.Evaporation.LiquorValve productValve(KvMax=6) "Product valve (flash level loop)";
  TrackingBox.Evaporation.Sources.LiquorSink productSink(p=productSinkP) "Product line";
  TrackingBox.Evaporation.CondensateTank condTank "Condensate tank";
  TrackingBox.Evaporation.LiquorValve condValve(KvMax=8) "Condensate valve (condensate level loop)";
  TrackingBox.Evaporation.Sources.LiquorSink condSink(p=condensateSinkP) "Condensate line";
  TrackingBox.Fluid.Sources.PressureSource steamSource(use_p_in=true, T=416) "Steam header";
  TrackingBox.Fluid.Sources.PressureSink vapourSink(use_p_in=true) "Next effect (vapour)";
  TrackingBox.Fluid.Sources.PressureSink condVapourSink(use_p_in=true) "Next effect (condensate flash)";
  TrackingBox.Fluid.Sources.PressureSink flashVapourSink(p=flashSinkP) "Flash-vapour header";
  TrackingBox.Evaporation.LevelTransmitter LT_body(rho_cal=1450) "Effect level transmitter";
  TrackingBox.Evaporation.LevelTransmitter LT_flash(rho_cal=1450) "Flash-tank level transmitter";
  TrackingBox.Evaporation.LevelTransmitter LT_condensate(rho_cal=950) "Condensate-tank level transmitter";
  TrackingBox.Evaporation.DrySolidsMeter DS_product "Product DS meter";
  TrackingBox.Evaporation.SmoothPI FIC_feed(k=0.1, Ti=10, Tt=10, Tf=1, y_start=0.6, use_hold_in=true, hold=holdControllers + holdFlowController) "Inlet flow loop";
  TrackingBox.Evaporation.SmoothPI LIC_body(k=-5, Ti=1200, Tt=120, Tf=2, y_start=0.5, use_hold_in=true, hold=holdControllers + holdLevelControllers + holdBodyLevelController) "Effect level loop";
  TrackingBox.Evaporation.SmoothPI LIC_flash(k=-3, Ti=1200, Tt=120, Tf=2, y_start=0.45, use_hold_in=true, hold=holdControllers + holdLevelControllers + holdFlashLevelController) "Flash-tank level loop";
  TrackingBox.Evaporation.SmoothPI LIC_condensate(k=-2, Ti=1200, Tt=120, Tf=2, y_start=0.5, use_hold_in=true, hold=holdControllers + holdLevelControllers + holdCondensateLevelController) "Condensate level loop";
equation
  connect(feedT, feedSource.T_in);
  connect(feedDS, feedSource.x_in);
  connect(feedSource.port, inletValve.port_a);
  connect(inletValve.port_b, effect.port_a);
  connect(effect.port_b, outletValve.port_a);
  connect(outletValve.port_b, flash.port_a);
  connect(flash.port_b, pump.port_a);
  connect(pump.port_b, productValve.port_a);
  connect(pump.port_b, DS_product.port);
  connect(productValve.port_b, productSink.port);
  connect(steamP, steamSource.p_in);
  connect(steamSource.port, effect.port_s);
  connect(nextP, vapourSink.p_in);
  connect(nextP, condVapourSink.p_in);
  connect(effect.port_v, vapourSink.port);
  connect(effect.port_c, condTank.port_a);
  connect(condTank.port_v, condVapourSink.port);
  connect(condTank.port_b, condValve.port_a);
  connect(condValve.port_b, condSink.port);
  connect(flash.port_v, flashVapourSink.port);
  connect(effect.dp_level, LT_body.dp);
  connect(flash.dp_level, LT_flash.dp);
  connect(condTank.dp_level, LT_condensate.dp);
  connect(feedFlowSet, FIC_feed.u_s);
  FIC_feed.u_m = inletValve.m_flow;
  FIC_feed.y = inletValve.opening;
  LIC_body.u_s = bodyLevelSet;
  LIC_body.u_m = LT_body.y;
  LIC_body.y = outletValve.opening;
  LIC_flash.u_s = flashLevelSet;
  LIC_flash.u_m = LT_flash.y;
  LIC_flash.y = productValve.opening;
  LIC_condensate.u_s = condensateLevelSet;
  LIC_condensate.u_m = LT_condensate.y;
  LIC_condensate.y = condValve.opening;
  effect.steamOpening = tanh(steamRatio*TrackingBox.Evaporation.Functions.splus(inletValve.m_flow, 1e-3));
  FI_feed = inletValve.m_flow;
  FI_product = productValve.m_flow;
  FI_condensate = effect.m_c;
  FI_steam = effect.m_steam;
  PI_vapour = effect.p_vap;
  PI_flash = flash.p_vap;
  PI_steamChest = effect.p_s;
  PI_pump = pump.port_b.p;
  TI_body = effect.T;
  TI_flash = flash.T;
  LI_body = LT_body.y;
  LI_flash = LT_flash.y;
  LI_condensate = LT_condensate.y;
  DI_product = DS_product.y;
  ZI_inlet = FIC_feed.y;
  ZI_outlet = LIC_body.y;
  ZI_product = LIC_flash.y;
  ZI_condensate = LIC_condensate.y;
  ZI_steam = effect.steamOpening;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-100,100},{100,-100}}, lineColor={0,0,0}, fillColor={245,245,245}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-70,60},{-30,-40}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-70,-10},{-30,-40}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Solid),
      Line(points={{-60,55},{-60,-5}}, color={238,46,47}),
      Line(points={{-40,55},{-40,-5}}, color={238,46,47}),
      Rectangle(extent={{10,40},{40,-40}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{10,-15},{40,-40}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Solid),
      Line(points={{-50,-40},{-50,-50},{25,-50},{25,-40}}, color={139,90,43}, thickness=0.5),
      Text(extent={{-150,145},{150,105}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Design point (1/10 scale of the last effect of the evaporator notes,
section 2): feed 2 kg/s at 52 % DS and 95 &deg;C, product about 1.35 kg/s at
77-78 % DS, steam header 4 bar(a) (chest about 3.5 bar), vapour to the next
effect at 1.4 bar, body about 131 &deg;C with a boiling-point rise of about
20 K, evaporation about 0.65 kg/s.</p>
<p>Control: the inlet flow loop <code>FIC_feed</code> (inlet valve, equal
percentage) follows <code>feedFlowSet</code> from a source at the fixed
pressure <code>feedSourceP</code>; the level loops open their outlet valves on
high level; the steam valve opens in ratio to the measured feed
(<code>tanh(steamRatio&middot;FI_feed)</code>), so that in a flow stoppage the
steam is shut off with the feed and the effect neither boils dry nor floods.
All controllers are smooth (<code>Evaporation.SmoothPI</code>) and can be
frozen (output held, bumpless release) by group, for step tests that keep some
loops active: <code>holdControllers</code> freezes all of them,
<code>holdFlowController</code> the inlet flow loop,
<code>holdLevelControllers</code> the three level loops, and
<code>holdBodyLevelController</code>, <code>holdFlashLevelController</code>,
<code>holdCondensateLevelController</code> one level loop each. A controller is
held while the sum of the inputs that reach it is above 0.5 (each input 0 or 1).
Freezing the level loops with the flow loop active (the source's practice)
lets an inlet-valve capacity error show in the inlet valve position.
<code>PI_pump</code>, the pump's discharge pressure, is what shows the pump's
wear when the flash level loop is active (the loop then sets the product
flow, and a weaker pump only opens the product valve further).</p>
</html>"));
end PartialSlice;
