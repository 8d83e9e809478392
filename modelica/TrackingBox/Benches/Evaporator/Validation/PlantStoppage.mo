within TrackingBox.Benches.Evaporator.Validation;
model PlantStoppage "Plant through a one-hour feed stoppage"
  extends TrackingBox.Icons.Example;
  TrackingBox.Benches.Evaporator.Plant bench "Model under test";
equation
  bench.feedFlowSet = 2 - 1.99*TrackingBox.Blocks.smoothStep(time, 3600, 60) + 1.99*TrackingBox.Blocks.smoothStep(time, 7260, 60);
  bench.feedDS = 0.52;
  bench.feedT = 368.15;
  bench.steamP = 4e5;
  bench.nextP = 1.4e5;
  bench.holdControllers = 0;
  bench.holdFlowController = 0;
  bench.holdLevelControllers = 0;
  bench.holdBodyLevelController = 0;
  bench.holdFlashLevelController = 0;
  bench.holdCondensateLevelController = 0;
  annotation (experiment(StopTime=14400, Tolerance=1e-6), Documentation(info="<html>
<p>Constant boundaries at the design point; the feed setpoint goes from 2 to
0.01 kg/s within a minute at 1 h, stays there for one hour and comes back
within a minute (the flow stoppage of the evaporator notes). The levels must
stay inside their vessels and the temperatures must not jump.</p>
</html>"));
end PlantStoppage;
