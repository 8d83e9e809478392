within TrackingBox.Benches.EvaporatorTrain.BaseClasses;
partial model PartialTrain "N-effect backward-feed train: effects, vapour headers, product flash tank, condensate cascade, condenser boundary"
  import TrackingBox.Media.Water.Saturation;
  parameter Integer N(min=2) = 7 "Number of effects (structural; effect 1 takes the live steam and gives the product)";
  // design point (it sizes areas, valves, pumps and the start values; the boundaries are inputs)
  parameter TrackingBox.Units.MassFlowRate feedFlowDesign = 18 "Design weak-liquor feed";
  parameter TrackingBox.Units.Fraction feedDSDesign = 0.15 "Design feed dry solids";
  parameter TrackingBox.Units.Fraction productDSDesign = 0.80 "Design product dry solids";
  parameter TrackingBox.Units.Temperature feedTDesign = 358.15 "Design feed temperature";
  parameter TrackingBox.Units.Pressure steamChestPDesign = 3.5e5 "Design steam-chest pressure of effect 1";
  parameter TrackingBox.Units.Pressure condenserPDesign = 1.4e4 "Design condenser pressure";
  parameter TrackingBox.Units.Pressure feedSourceP = 3e5 "Pressure of the weak-liquor source ahead of the inlet valve";
  parameter TrackingBox.Units.Pressure productSinkP = 3e5 "Pressure at the end of the product line";
  parameter TrackingBox.Units.Pressure condensateSinkP = 5e3 "Pressure at the suction of the condensate pump (end of the cascade)";
  parameter TrackingBox.Units.Height bodyLevelSet = 1.2 "Setpoint of every effect level (as read by LI_body)";
  parameter TrackingBox.Units.Height flashLevelSet = 1.0 "Setpoint of the product flash-tank level";
  parameter TrackingBox.Units.Height condensateLevelSet = 0.8 "Setpoint of every condensate-tank level";
  parameter TrackingBox.Units.PressureDifference transferPumpDp0 = 2e5 "Shut-off head of the transfer pumps";
  parameter Real steamRatio(unit="s/kg") = 0.048 "Live-steam valve opening = tanh(steamRatio*FI_feed) (ratio station)";
  parameter TrackingBox.Units.Acceleration g = 9.81 "Gravity";
  // what plant and twin set differently (structural flags and per-effect values)
  parameter Boolean useRfInput = false "= true: every effect takes its fouling resistance from its input Rf_in (plant)";
  parameter Boolean useCorrectionInputs = false "= true: every vessel has a correction-flow input (twin)";
  parameter TrackingBox.Units.Fraction ventFractionAll(min=0, max=0.02) = 0 "Steam vented from every chest (fraction of its condensate; the default of ventFractionEffect)";
  parameter TrackingBox.Units.ThermalConductance UA_lossAll(min=0, max=1000) = 0 "Heat-loss conductance of every effect's liquor to ambient (the default of UA_lossEffect)";
  parameter TrackingBox.Units.Fraction ventFractionEffect[N] = fill(ventFractionAll, N) "Steam vented from each chest (fraction of its condensate)";
  parameter TrackingBox.Units.ThermalConductance UA_lossEffect[N] = fill(UA_lossAll, N) "Heat-loss conductance of each effect";
  parameter TrackingBox.Units.ThermalConductance UA_lossFlash = 0 "Heat-loss conductance of the product flash tank";
  parameter TrackingBox.Units.Fraction DSbias = 0 "Bias of the product DS meter";
  parameter Real DSdrift(unit="1/s") = 0 "Drift of the product DS meter";
  // derived design (backward feed, equal evaporation and equal driving temperature difference per effect)
  parameter TrackingBox.Units.MassFlowRate productFlowDesign = feedFlowDesign*feedDSDesign/productDSDesign "Design product flow";
  parameter TrackingBox.Units.MassFlowRate evapDesign = (feedFlowDesign - productFlowDesign)/N "Design evaporation per effect";
  parameter Real a_x(unit="1") = feedFlowDesign*feedDSDesign/evapDesign "x_k = a_x/(b_x + k)";
  parameter Real b_x(unit="1") = productFlowDesign/evapDesign - 1 "Liquor out of effect k = evapDesign*(b_x + k)";
  parameter TrackingBox.Units.Fraction xDesign[N] = {a_x/(b_x + k) for k in 1:N} "Design dry solids leaving each effect";
  parameter TrackingBox.Units.TemperatureDifference BPRDesign[N] = {6.173*xDesign[k] - 7.48*xDesign[k]^1.5 + 32.747*xDesign[k]^2 for k in 1:N} "Design boiling-point rise (at 1 atm)";
  parameter TrackingBox.Units.TemperatureDifference cumBPRDesign[N] = {BPRDesign[1] + 6.173*a_x*(log(b_x + k + 0.5) - log(b_x + 1.5)) + 14.96*a_x^1.5*(1/sqrt(b_x + k + 0.5) - 1/sqrt(b_x + 1.5)) - 32.747*a_x^2*(1/(b_x + k + 0.5) - 1/(b_x + 1.5)) for k in 1:N} "Boiling-point rises of effects 1..k summed (midpoint rule beyond the first)";
  parameter TrackingBox.Units.Temperature TSteamChestDesign = Saturation.TSat(steamChestPDesign) "Design condensing temperature of effect 1";
  parameter TrackingBox.Units.Temperature TCondenserDesign = Saturation.TSat(condenserPDesign) "Design condenser temperature";
  parameter TrackingBox.Units.TemperatureDifference dTDesign = (TSteamChestDesign - TCondenserDesign - cumBPRDesign[N])/N "Design driving temperature difference per effect";
  parameter TrackingBox.Units.Temperature TVapDesign[N] = {TSteamChestDesign - k*dTDesign - cumBPRDesign[k] for k in 1:N} "Design vapour temperatures";
  parameter TrackingBox.Units.Temperature TLiqDesign[N] = {TVapDesign[k] + BPRDesign[k] for k in 1:N} "Design liquor temperatures";
  parameter TrackingBox.Units.Temperature TSteamDesign[N] = {TLiqDesign[k] + dTDesign for k in 1:N} "Design condensing temperatures";
  parameter TrackingBox.Units.Temperature TInDesign[N] = {if k < N then TSteamChestDesign - (k + 1)*dTDesign - cumBPRDesign[k] else feedTDesign for k in 1:N} "Design temperature of the liquor entering each effect";
  parameter TrackingBox.Units.Pressure pVapDesign[N] = {exp(23.2116 - 3830.30/(TVapDesign[k] - 45.360)) for k in 1:N} "Design vapour pressures";
  parameter TrackingBox.Units.Pressure pSteamDesign[N] = {exp(23.2116 - 3830.30/(TSteamDesign[k] - 45.360)) for k in 1:N} "Design steam-chest pressures";
  parameter TrackingBox.Units.Density rhoDesign[N] = {0.97*(997 + 649*xDesign[k]) for k in 1:N} "Design liquor densities";
  parameter TrackingBox.Units.HeatFlowRate QDesign[N] = {evapDesign*(2.501e6 - 2400*(TVapDesign[k] - 273.15)) + evapDesign*(b_x + k + 1)*(4216 - 2541*xDesign[k])*(TLiqDesign[k] - TInDesign[k]) for k in 1:N} "Design duties";
  parameter TrackingBox.Units.CoefficientOfHeatTransfer UDesign[N] = {2200*0.25^((xDesign[k] - 0.15)/0.65) for k in 1:N} "Design overall coefficients (2.2 kW/m2K at 15 % DS to 0.55 at 80 %)";
  parameter TrackingBox.Units.Area ADesign[N] = {QDesign[k]/(UDesign[k]*dTDesign) for k in 1:N} "Heat-transfer areas";
  parameter Real nuDesign[N](each unit="m2/s") = {1e-6*exp(-2.4273 + 3.3532*xDesign[k] + 3.7654*xDesign[k]^2 - 2.49*xDesign[k]^3 + (6.1347e7 - 5.442e7*xDesign[k] + 2.1915e8*xDesign[k]^2 + 1.7042e8*xDesign[k]^3)/TLiqDesign[k]^3) for k in 1:N} "Design liquor viscosities (reference of each effect's clean coefficient)";
  parameter TrackingBox.Units.MassFlowRate steamDesign = QDesign[1]/(2.501e6 - 2400*(TSteamChestDesign - 273.15)) "Design live steam";
  parameter TrackingBox.Units.MassFlowRate condensateDesign[N] = {steamDesign + (k - 1)*evapDesign for k in 1:N} "Design flow out of each condensate tank (the cascade)";
  parameter TrackingBox.Units.PressureDifference dpTransferDesign[N - 1] = {0.75*transferPumpDp0 + rhoDesign[k + 1]*g*(bodyLevelSet + 5) + pVapDesign[k + 1] - pVapDesign[k] for k in 1:N - 1} "Design pressure drop over the transfer valves";
  parameter TrackingBox.Units.PressureDifference dpCondensateDesign[N] = {pVapDesign[k] - (if k < N then pVapDesign[k + 1] else condensateSinkP) + 950*g*(condensateLevelSet + 1) for k in 1:N} "Design pressure drop over the condensate valves";
  parameter TrackingBox.Units.PressureDifference dpOutletDesign = rhoDesign[1]*g*(bodyLevelSet + 5) + pVapDesign[1] - pVapDesign[2] "Design pressure drop over the product outlet valve of effect 1";
  TrackingBox.Interfaces.RealInput feedFlowSet(unit="kg/s", start=18) "Setpoint of the feed flow loop"
    annotation (Placement(transformation(extent={{-114,83},{-100,97}})));
  TrackingBox.Interfaces.RealInput feedDS(unit="1", start=0.15) "Dry-solids fraction of the weak liquor"
    annotation (Placement(transformation(extent={{-114,65},{-100,79}})));
  TrackingBox.Interfaces.RealInput feedT(unit="K", start=358.15) "Temperature of the weak liquor"
    annotation (Placement(transformation(extent={{-114,47},{-100,61}})));
  TrackingBox.Interfaces.RealInput steamP(unit="Pa", start=4e5) "Pressure of the live-steam header"
    annotation (Placement(transformation(extent={{-114,29},{-100,43}})));
  TrackingBox.Interfaces.RealInput condenserP(unit="Pa", start=1.4e4) "Pressure of the surface condenser"
    annotation (Placement(transformation(extent={{-114,11},{-100,25}})));
  TrackingBox.Interfaces.RealInput holdControllers(unit="1", start=0) "> 0.5 freezes all PI controllers (outputs held)"
    annotation (Placement(transformation(extent={{-114,-7},{-100,7}})));
  TrackingBox.Interfaces.RealInput holdFlowController(unit="1", start=0) "> 0.5 freezes the feed flow loop"
    annotation (Placement(transformation(extent={{-114,-25},{-100,-11}})));
  TrackingBox.Interfaces.RealInput holdLevelControllers(unit="1", start=0) "> 0.5 freezes every level loop"
    annotation (Placement(transformation(extent={{-114,-43},{-100,-29}})));
  TrackingBox.Interfaces.RealInput holdBodyLevelControllers(unit="1", start=0) "> 0.5 freezes the effects' level loops"
    annotation (Placement(transformation(extent={{-114,-61},{-100,-47}})));
  TrackingBox.Interfaces.RealInput holdFlashLevelController(unit="1", start=0) "> 0.5 freezes the product flash-tank level loop"
    annotation (Placement(transformation(extent={{-114,-79},{-100,-65}})));
  TrackingBox.Interfaces.RealInput holdCondensateLevelControllers(unit="1", start=0) "> 0.5 freezes the condensate-tank level loops"
    annotation (Placement(transformation(extent={{-114,-97},{-100,-83}})));
  TrackingBox.Interfaces.RealOutput FI_feed(unit="kg/s") "Weak-liquor feed"
    annotation (Placement(transformation(extent={{100,86},{108,94}})));
  TrackingBox.Interfaces.RealOutput FI_product(unit="kg/s") "Product liquor flow"
    annotation (Placement(transformation(extent={{100,76},{108,84}})));
  TrackingBox.Interfaces.RealOutput FI_steam(unit="kg/s") "Live steam into effect 1"
    annotation (Placement(transformation(extent={{100,66},{108,74}})));
  TrackingBox.Interfaces.RealOutput FI_liquor[N](each unit="kg/s") "Liquor leaving each effect (transfer flow; effect 1: to the flash tank)"
    annotation (Placement(transformation(extent={{100,56},{108,64}})));
  TrackingBox.Interfaces.RealOutput FI_condensate[N](each unit="kg/s") "Condensate leaving each condensate tank"
    annotation (Placement(transformation(extent={{100,46},{108,54}})));
  TrackingBox.Interfaces.RealOutput PI_vapour[N](each unit="Pa") "Pressure in each effect's vapour space"
    annotation (Placement(transformation(extent={{100,36},{108,44}})));
  TrackingBox.Interfaces.RealOutput PI_steamChest[N](each unit="Pa") "Pressure in each steam chest"
    annotation (Placement(transformation(extent={{100,26},{108,34}})));
  TrackingBox.Interfaces.RealOutput PI_flash(unit="Pa") "Pressure in the product flash tank"
    annotation (Placement(transformation(extent={{100,16},{108,24}})));
  TrackingBox.Interfaces.RealOutput TI_body[N](each unit="K") "Liquor temperature in each effect"
    annotation (Placement(transformation(extent={{100,6},{108,14}})));
  TrackingBox.Interfaces.RealOutput TI_flash(unit="K") "Product temperature after the flash tank"
    annotation (Placement(transformation(extent={{100,-4},{108,4}})));
  TrackingBox.Interfaces.RealOutput LI_body[N](each unit="m") "Level of each effect (dP transmitter)"
    annotation (Placement(transformation(extent={{100,-14},{108,-6}})));
  TrackingBox.Interfaces.RealOutput LI_flash(unit="m") "Level of the product flash tank"
    annotation (Placement(transformation(extent={{100,-24},{108,-16}})));
  TrackingBox.Interfaces.RealOutput LI_condensate[N](each unit="m") "Level of each condensate tank"
    annotation (Placement(transformation(extent={{100,-34},{108,-26}})));
  TrackingBox.Interfaces.RealOutput DI_product(unit="1") "Product dry solids (DS meter)"
    annotation (Placement(transformation(extent={{100,-44},{108,-36}})));
  TrackingBox.Interfaces.RealOutput ZI_inlet(unit="1") "Feed valve position"
    annotation (Placement(transformation(extent={{100,-54},{108,-46}})));
  TrackingBox.Interfaces.RealOutput ZI_steam(unit="1") "Live-steam valve position"
    annotation (Placement(transformation(extent={{100,-64},{108,-56}})));
  TrackingBox.Interfaces.RealOutput ZI_body[N](each unit="1") "Position of each effect's level valve"
    annotation (Placement(transformation(extent={{100,-74},{108,-66}})));
  TrackingBox.Interfaces.RealOutput ZI_product(unit="1") "Product valve position (flash-tank level loop)"
    annotation (Placement(transformation(extent={{100,-84},{108,-76}})));
  TrackingBox.Interfaces.RealOutput ZI_condensate[N](each unit="1") "Position of each condensate valve"
    annotation (Placement(transformation(extent={{100,-94},{108,-86}})));
  TrackingBox.Evaporation.Sources.LiquorSource feedSource(p=feedSourceP, use_T_in=true, use_x_in=true) "Weak liquor from the storage tank";
  TrackingBox.Evaporation.LiquorValve inletValve(KvMax=feedFlowDesign*3600/(0.2121*sqrt(rhoDesign[N]*(feedSourceP - pVapDesign[N])/100)), equalPercentage=true) "Feed valve (flow loop) into effect N";
  TrackingBox.Evaporation.Effect effect[N](
    each use_Rf_in=useRfInput, each use_m_flow_corr_in=useCorrectionInputs,
    A=ADesign, U0=UDesign, nu_ref=nuDesign, each A_sump=4, each V_hold=1, each H=3, each z_out=5,
    each V_vap=20, T_ref_vap=TVapDesign, m_flow_vap_nominal=fill(evapDesign, N), dp_vap_nominal={0.02*pVapDesign[k] for k in 1:N}, dp_vap_small={0.005*pVapDesign[k] for k in 1:N},
    K_ev=fill(5*evapDesign, N), m_flow_rec={3*evapDesign*(b_x + k + 1) for k in 1:N},
    each V_steam=5, T_ref_steam=TSteamDesign,
    m_flow_steam_nominal={if k == 1 then 1.5*steamDesign else 1.1*evapDesign for k in 1:N},
    dp_steam_nominal={if k == 1 then 5e4 else 0.02*pSteamDesign[k] for k in 1:N},
    dp_steam_small={if k == 1 then 1000 else 0.005*pSteamDesign[k] for k in 1:N},
    ventFraction=ventFractionEffect, UA_loss=UA_lossEffect,
    x_start=xDesign, T_start=TLiqDesign, each L_start=bodyLevelSet, p_start=pVapDesign, p_steam_start=pSteamDesign) "The effects (1: live steam, product; N: feed, condenser)";
  TrackingBox.Evaporation.LiquorPump transferPump[N - 1](
    each dp0=transferPumpDp0, VMax={2*evapDesign*(b_x + k + 1)/rhoDesign[k + 1] for k in 1:N - 1}) "transferPump[k] moves the liquor of effect k+1 towards effect k";
  TrackingBox.Evaporation.LiquorValve transferValve[N - 1](
    KvMax={evapDesign*(b_x + k + 1)*3600/(0.5*sqrt(rhoDesign[k + 1]*dpTransferDesign[k]/100)) for k in 1:N - 1}) "transferValve[k]: level valve of effect k+1";
  TrackingBox.Evaporation.LiquorValve outletValve(KvMax=productFlowDesign*3600/(0.5*sqrt(rhoDesign[1]*dpOutletDesign/100))) "Level valve of effect 1 (to the product flash tank)";
  TrackingBox.Evaporation.FlashTank flash(
    A_sump=2, V_hold=0.3, H=3, z_out=2, V_vap=5, T_ref_vap=TVapDesign[2], m_flow_vap_nominal=0.3, dp_vap_nominal=3000, K_ev=2,
    UA_loss=UA_lossFlash, use_m_flow_corr_in=useCorrectionInputs,
    x_start=productDSDesign, T_start=TVapDesign[2] + BPRDesign[1], L_start=flashLevelSet, p_start=pVapDesign[2]) "Product flash tank (its vapour joins effect 2's)";
  TrackingBox.Evaporation.LiquorPump productPump(dp0=4e5, VMax=2*productFlowDesign/rhoDesign[1]) "Product pump";
  TrackingBox.Evaporation.LiquorValve productValve(KvMax=productFlowDesign*3600/(0.5*sqrt(rhoDesign[1]*(pVapDesign[2] + rhoDesign[1]*g*(flashLevelSet + 2) + 3e5 - productSinkP)/100))) "Product valve (flash-tank level loop)";
  TrackingBox.Evaporation.Sources.LiquorSink productSink(p=productSinkP) "Product line to the concentrate tank";
  TrackingBox.Evaporation.CondensateTank condTank[N](
    each use_m_flow_corr_in=useCorrectionInputs, each A_sump=2, each V_hold=0.2, each H=2, each z_out=1, each V_vap=2,
    T_ref_vap=TVapDesign, m_flow_vap_nominal={0.08*condensateDesign[k] for k in 1:N}, dp_vap_nominal={0.05*pVapDesign[k] for k in 1:N}, dp_vap_small={0.01*pVapDesign[k] for k in 1:N},
    K_ev=condensateDesign, each x_start=0, T_start=TVapDesign, each L_start=condensateLevelSet, p_start=pVapDesign) "condTank[k] receives the condensate of effect k (and the cascade) and flashes into header k";
  TrackingBox.Evaporation.LiquorValve condValve[N](
    KvMax={condensateDesign[k]*3600/(0.5*sqrt(950*dpCondensateDesign[k]/100)) for k in 1:N}) "Condensate valves (condensate level loops)";
  CondensateMixer condMixer[N - 1] "condMixer[k]: the cascade from tank k joins the condensate of effect k+1";
  TrackingBox.Evaporation.Sources.LiquorSink condSink(p=condensateSinkP) "End of the condensate cascade";
  VapourHeader header[N](each nPorts=3, each V=30, T_ref=TVapDesign, p_start=pVapDesign) "header[k]: vapour of effect k (with its condensate flash) to effect k+1 or the condenser";
  VapourPlug plug[N - 1] "Closes the third inlet of every header but header 2";
  TrackingBox.Fluid.Sources.PressureSource steamSource(use_p_in=true, T=416) "Live-steam header";
  VapourLine condenserLine(m_flow_nominal=evapDesign, dp_nominal=0.02*condenserPDesign, dp_small=0.005*condenserPDesign) "Vapour line from the last header into the condenser";
  TrackingBox.Fluid.Sources.PressureSink condenser(use_p_in=true) "Surface condenser";
  TrackingBox.Evaporation.LevelTransmitter LT_body[N](rho_cal=rhoDesign) "Effect level transmitters (calibrated at the design density)";
  TrackingBox.Evaporation.LevelTransmitter LT_flash(rho_cal=rhoDesign[1]) "Flash-tank level transmitter";
  TrackingBox.Evaporation.LevelTransmitter LT_condensate[N](each rho_cal=950) "Condensate level transmitters";
  TrackingBox.Evaporation.DrySolidsMeter DS_product(bias=DSbias, drift=DSdrift) "Product DS meter";
  TrackingBox.Evaporation.SmoothPI FIC_feed(k=0.011, Ti=10, Tt=10, Tf=1, y_start=0.6, use_hold_in=true) "Feed flow loop";
  TrackingBox.Evaporation.SmoothPI LIC_body[N](each k=-5, each Ti=600, each Tt=120, each Tf=2, each y_start=0.5, each use_hold_in=true) "Effect level loops";
  TrackingBox.Evaporation.SmoothPI LIC_flash(k=-3, Ti=600, Tt=120, Tf=2, y_start=0.5, use_hold_in=true) "Flash-tank level loop";
  TrackingBox.Evaporation.SmoothPI LIC_condensate[N](each k=-2, each Ti=600, each Tt=120, each Tf=2, each y_start=0.5, each use_hold_in=true) "Condensate level loops";
equation
  // liquor: feed into effect N, backward from effect k+1 to effect k, product from effect 1
  connect(feedT, feedSource.T_in);
  connect(feedDS, feedSource.x_in);
  connect(feedSource.port, inletValve.port_a);
  connect(inletValve.port_b, effect[N].port_a);
  for k in 1:N - 1 loop
    connect(effect[k + 1].port_b, transferPump[k].port_a);
    connect(transferPump[k].port_b, transferValve[k].port_a);
    connect(transferValve[k].port_b, effect[k].port_a);
  end for;
  connect(effect[1].port_b, outletValve.port_a);
  connect(outletValve.port_b, flash.port_a);
  connect(flash.port_b, productPump.port_a);
  connect(productPump.port_b, productValve.port_a);
  connect(productPump.port_b, DS_product.port);
  connect(productValve.port_b, productSink.port);
  // vapour: live steam into effect 1, header k into effect k+1, header N into the condenser
  connect(steamP, steamSource.p_in);
  connect(steamSource.port, effect[1].port_s);
  for k in 1:N loop
    connect(effect[k].port_v, header[k].port_a[1]);
    connect(condTank[k].port_v, header[k].port_a[2]);
  end for;
  for k in 1:N - 1 loop
    connect(header[k].port_b, effect[k + 1].port_s);
  end for;
  connect(header[N].port_b, condenserLine.port_a);
  connect(condenserLine.port_b, condenser.port);
  connect(condenserP, condenser.p_in);
  connect(flash.port_v, header[2].port_a[3]);
  connect(plug[1].port, header[1].port_a[3]);
  for k in 3:N loop
    connect(plug[k - 1].port, header[k].port_a[3]);
  end for;
  // condensate cascade: tank k -> valve k -> (joins effect k+1's condensate) -> tank k+1
  connect(effect[1].port_c, condTank[1].port_a);
  for k in 1:N - 1 loop
    connect(condTank[k].port_b, condValve[k].port_a);
    connect(condValve[k].port_b, condMixer[k].port_a2);
    connect(effect[k + 1].port_c, condMixer[k].port_a1);
    connect(condMixer[k].port_b, condTank[k + 1].port_a);
  end for;
  connect(condTank[N].port_b, condValve[N].port_a);
  connect(condValve[N].port_b, condSink.port);
  // instruments
  for k in 1:N loop
    connect(effect[k].dp_level, LT_body[k].dp);
    connect(condTank[k].dp_level, LT_condensate[k].dp);
  end for;
  connect(flash.dp_level, LT_flash.dp);
  // control
  connect(feedFlowSet, FIC_feed.u_s);
  FIC_feed.u_m = inletValve.m_flow;
  FIC_feed.y = inletValve.opening;
  FIC_feed.hold = holdControllers + holdFlowController;
  for k in 1:N loop
    LIC_body[k].u_s = bodyLevelSet;
    LIC_body[k].u_m = LT_body[k].y;
    LIC_body[k].hold = holdControllers + holdLevelControllers + holdBodyLevelControllers;
    LIC_condensate[k].u_s = condensateLevelSet;
    LIC_condensate[k].u_m = LT_condensate[k].y;
    LIC_condensate[k].y = condValve[k].opening;
    LIC_condensate[k].hold = holdControllers + holdLevelControllers + holdCondensateLevelControllers;
  end for;
  LIC_body[1].y = outletValve.opening;
  for k in 1:N - 1 loop
    LIC_body[k + 1].y = transferValve[k].opening;
  end for;
  LIC_flash.u_s = flashLevelSet;
  LIC_flash.u_m = LT_flash.y;
  LIC_flash.y = productValve.opening;
  LIC_flash.hold = holdControllers + holdLevelControllers + holdFlashLevelController;
  effect[1].steamOpening = tanh(steamRatio*TrackingBox.Evaporation.Functions.splus(inletValve.m_flow, 1e-3));
  for k in 2:N loop
    effect[k].steamOpening = 1;
  end for;
  // measurements
  FI_feed = inletValve.m_flow;
  FI_product = productValve.m_flow;
  FI_steam = effect[1].m_steam;
  FI_liquor[1] = outletValve.m_flow;
  for k in 2:N loop
    FI_liquor[k] = transferValve[k - 1].m_flow;
  end for;
  for k in 1:N loop
    FI_condensate[k] = condValve[k].m_flow;
    PI_vapour[k] = effect[k].p_vap;
    PI_steamChest[k] = effect[k].p_s;
    TI_body[k] = effect[k].T;
    LI_body[k] = LT_body[k].y;
    LI_condensate[k] = LT_condensate[k].y;
    ZI_body[k] = LIC_body[k].y;
    ZI_condensate[k] = LIC_condensate[k].y;
  end for;
  PI_flash = flash.p_vap;
  TI_flash = flash.T;
  LI_flash = LT_flash.y;
  DI_product = DS_product.y;
  ZI_inlet = FIC_feed.y;
  ZI_steam = effect[1].steamOpening;
  ZI_product = LIC_flash.y;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-100,100},{100,-100}}, lineColor={0,0,0}, fillColor={245,245,245}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-75,50},{-45,-30}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-75,-5},{-45,-30}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-35,50},{-5,-30}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-35,-5},{-5,-30}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{5,50},{35,-30}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{5,-5},{35,-30}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{45,50},{75,-30}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{45,-5},{75,-30}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Solid),
      Line(points={{75,-40},{-60,-40}}, color={139,90,43}, thickness=0.5, arrow={Arrow.None, Arrow.Filled}),
      Text(extent={{-90,90},{90,60}}, textString="N = %N", textColor={0,0,0}),
      Text(extent={{-150,145},{150,105}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Backward feed: the weak liquor enters effect <code>N</code> (the coldest,
at the condenser's end) through the flow-controlled feed valve; the liquor of
effect <code>k+1</code> is pumped into effect <code>k</code> through the level
valve of effect <code>k+1</code>; effect 1 (live steam, highest dry solids)
gives the product through its level valve into the product flash tank, whose
vapour joins effect 2's. The vapour of effect <code>k</code> and the flash of
condensate tank <code>k</code> meet in <code>header[k]</code>, which feeds the
steam chest of effect <code>k+1</code> (the surface condenser, a pressure
boundary, for <code>k = N</code>). The condensate cascades: tank
<code>k</code> takes the condensate of effect <code>k</code> and the outflow of
tank <code>k-1</code>, flashes to header <code>k</code>'s pressure and sends
its liquid on; the last tank drains to the condensate pump's suction.</p>
<p>The design point (it sizes every area, valve and pump and sets the start
values) follows the evaporator notes' illustrative 7-effect train at 1/10
scale: feed 18 kg/s at 15 % DS to 80 %, live steam 3.5 bar in the chest,
condenser 14 kPa, equal evaporation and equal driving temperature difference
per effect, U from 2.2 kW/m2K (15 % DS) to 0.55 (80 %). It is written for any
<code>N</code> (closed forms of <code>k</code>; the boiling-point rises are
summed with the midpoint rule), so changing <code>N</code> alone gives a
consistent train.</p>
<p>Control as in the single-effect bench: a feed flow loop, one level loop per
vessel (high level opens the outlet), the live-steam valve in ratio to the
measured feed; every controller can be frozen by group
(<code>holdControllers</code>, <code>holdFlowController</code>,
<code>holdLevelControllers</code>, <code>holdBodyLevelControllers</code>,
<code>holdFlashLevelController</code>,
<code>holdCondensateLevelControllers</code>). Effects 2..N have their steam
valve fully open (it acts as the vapour line's inlet resistance).</p>
<p>The valves' and pumps' sizes (<code>KvMax</code>, <code>dp0</code>) are
calculated parameters (they follow the design); what wears is each component's own
tunable factor, <code>inletValve.capacity</code>, <code>outletValve.capacity</code>,
<code>transferValve[k].capacity</code>, <code>transferPump[k].head</code> (1 = as
designed), and each effect's boiling-point offset is its own <code>effect[k].dBPR</code>
(0 here): the plant sets them by modifiers, and a generated TrackingBox drives them
through the components' conditional inputs (<code>use_capacity_in</code>,
<code>use_head_in</code>, <code>use_dBPR_in</code>), as it drives <code>effect[k].Rf</code>.</p>
<p>Steam economy: every chest vents <code>ventFractionAll</code> of its condensate as
steam and every effect's liquor loses <code>UA_lossAll&middot;(T - T_amb)</code> to ambient
(0 by default; the per-effect arrays <code>ventFractionEffect</code>,
<code>UA_lossEffect</code> follow them). Both make the train draw more steam and vapour per
kilogram evaporated, which lowers every steam-chest and vapour pressure (on the 7-effect bench,
0.5 % vents and 200 W/K per effect: effect 1's chest 1.7 and 1.2 kPa lower); fouling, the only
time-varying parameter, can only raise them. The twin therefore has them as constants to estimate
and hold, like the boiling-point offsets.</p>
</html>"));
end PartialTrain;
