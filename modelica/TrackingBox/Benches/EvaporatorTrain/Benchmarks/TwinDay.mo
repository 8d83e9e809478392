within TrackingBox.Benches.EvaporatorTrain.Benchmarks;
model TwinDay "Twin (7 effects) through one day with a feed stoppage"
  extends TrackingBox.Icons.Example;
  TrackingBox.Benches.EvaporatorTrain.Twin bench "Model under test";
equation
  bench.feedFlowSet = 18 - 17.82*TrackingBox.Blocks.smoothStep(time, 36000, 60) + 17.82*TrackingBox.Blocks.smoothStep(time, 38400, 180);
  bench.feedDS = 0.15 + 0.005*sin(time/20000);
  bench.feedT = 358.15;
  bench.steamP = 4e5 - 1e4*TrackingBox.Blocks.smoothStep(time, 60000, 1800);
  bench.condenserP = 1.4e4;
  bench.holdControllers = 0;
  bench.holdFlowController = 0;
  bench.holdLevelControllers = 0;
  bench.holdBodyLevelControllers = 0;
  bench.holdFlashLevelController = 0;
  bench.holdCondensateLevelControllers = 0;
  bench.body_m_flow_corr = zeros(bench.N);
  bench.flash_m_flow_corr = 0;
  bench.cond_m_flow_corr = zeros(bench.N);
  annotation (experiment(StopTime=86400, Tolerance=1e-6), Documentation(info="<html>
<p>The design boundaries for one day (the compile and one-day simulation
benchmark of <code>scripts/bench_compile</code>): a 40-minute feed stoppage at
10 h (to 1 % of the feed within a minute, back over three minutes), feed dry
solids oscillating by 0.5 %DS, the live-steam header falling by 0.1 bar at
about 17 h. Every level must stay inside its vessel.</p>
</html>"));
end TwinDay;
