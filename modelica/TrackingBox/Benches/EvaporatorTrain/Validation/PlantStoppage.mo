within TrackingBox.Benches.EvaporatorTrain.Validation;
model PlantStoppage "3-effect plant through a 40-minute feed stoppage"
  extends TrackingBox.Icons.Example;
  TrackingBox.Benches.EvaporatorTrain.Plant bench(N=3) "Model under test";
equation
  bench.feedFlowSet = 18 - 17.82*TrackingBox.Blocks.smoothStep(time, 1800, 60) + 17.82*TrackingBox.Blocks.smoothStep(time, 4200, 180);
  bench.feedDS = 0.15;
  bench.feedT = 358.15;
  bench.steamP = 4e5;
  bench.condenserP = 1.4e4;
  bench.holdControllers = 0;
  bench.holdFlowController = 0;
  bench.holdLevelControllers = 0;
  bench.holdBodyLevelControllers = 0;
  bench.holdFlashLevelController = 0;
  bench.holdCondensateLevelControllers = 0;
  annotation (experiment(StopTime=7200, Tolerance=1e-6), Documentation(info="<html>
<p>Design boundaries; the feed setpoint goes from 18 to 0.18 kg/s within a
minute at 30 min, stays there for 40 minutes and comes back over three
minutes (the flow stoppage of the evaporator notes). The levels must stay
inside their vessels and the temperatures must not jump.</p>
</html>"));
end PlantStoppage;
