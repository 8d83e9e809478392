within TrackingBox.Benches.EvaporatorTrain.Validation;
model TrainBalance "Mass and dry-solids balances of a 3-effect twin train under varying boundaries and correction flows"
  extends TrackingBox.Icons.Example;
  parameter Integer N = 3 "Number of effects";
  TrackingBox.Benches.EvaporatorTrain.Twin train(N=N) "The train (twin variant: it has the correction-flow inputs)";
  TrackingBox.Units.Mass massIn(start=0, fixed=true) "Integral of the mass entering: feed, live steam, correction flows";
  TrackingBox.Units.Mass massOut(start=0, fixed=true) "Integral of the mass leaving: product, vapour to the condenser, condensate, steam vents";
  TrackingBox.Units.Mass solidsIn(start=0, fixed=true) "Integral of the dry solids entering: feed, correction flows";
  TrackingBox.Units.Mass solidsOut(start=0, fixed=true) "Integral of the dry solids leaving: product, condensate";
  TrackingBox.Units.Mass massInventory "Liquid and vapour masses of every vessel, steam chest and header";
  TrackingBox.Units.Mass solidsInventory "Dry-solids masses of every vessel";
  TrackingBox.Units.MassFlowRate throughput "Feed flow (the scale of the balances)";
equation
  train.feedFlowSet = 18 - 6*TrackingBox.Blocks.smoothStep(time, 1800, 120);
  train.feedDS = 0.15 + 0.01*sin(time/900);
  train.feedT = 358.15 + 3*sin(time/700);
  train.steamP = 4e5 + 2e4*sin(time/1200);
  train.condenserP = 1.4e4 + 1e3*sin(time/1500);
  train.holdControllers = 0;
  train.holdFlowController = 0;
  train.holdLevelControllers = 0;
  train.holdBodyLevelControllers = 0;
  train.holdFlashLevelController = 0;
  train.holdCondensateLevelControllers = 0;
  train.body_m_flow_corr = {0.05*sin(time/(500 + 100*k)) for k in 1:N};
  train.flash_m_flow_corr = 0.01*cos(time/500);
  train.cond_m_flow_corr = {0.02*cos(time/(400 + 50*k)) for k in 1:N};
  throughput = train.inletValve.m_flow;
  der(massIn) = train.inletValve.m_flow + train.effect[1].m_steam + sum(train.effect[k].m_corr + train.condTank[k].m_corr for k in 1:N) + train.flash.m_corr;
  der(massOut) = train.productValve.m_flow + train.condenserLine.m_flow + train.condValve[N].m_flow + sum(train.effect[k].m_vent for k in 1:N);
  der(solidsIn) = train.inletValve.port_a.x*train.inletValve.m_flow + sum(train.effect[k].x*train.effect[k].m_corr + train.condTank[k].x*train.condTank[k].m_corr for k in 1:N) + train.flash.x*train.flash.m_corr;
  der(solidsOut) = train.productValve.port_a.x*train.productValve.m_flow + train.condValve[N].port_a.x*train.condValve[N].m_flow;
  massInventory = sum(train.effect[k].M + train.effect[k].M_vap + train.effect[k].M_steam + train.condTank[k].M + train.condTank[k].M_vap + train.header[k].M for k in 1:N) + train.flash.M + train.flash.M_vap;
  solidsInventory = sum(train.effect[k].M_s + train.condTank[k].M_s for k in 1:N) + train.flash.M_s;
  annotation (experiment(StopTime=3600, Tolerance=1e-8), Documentation(info="<html>
<p>A 3-effect <code>Twin</code> driven by a feed reduction from 18 to 12 kg/s
at 30 min, oscillating feed dry solids and temperature, live-steam and
condenser pressures, and oscillating correction flows into every vessel.
Four integrator states accumulate what crosses the train's boundary; the
conservation laws say
<code>massInventory(t) - massInventory(0) = massIn - massOut</code> (liquids,
vapour spaces, steam chests and headers) and
<code>solidsInventory(t) - solidsInventory(0) = solidsIn - solidsOut</code>.
The test <code>tests/test_evaporator_train.py</code> checks both from the
FMU's outputs.</p>
</html>"));
end TrainBalance;
