within TrackingBox.Benches.EvaporatorTrain;
package Validation "Plant and twin driven by time functions over one day"
  annotation (Documentation(info="<html>
<p>Three-effect trains, small enough for the test suite:
<code>PlantStoppage</code> runs the plant through a 40-minute feed stoppage
(levels inside their vessels, no jumps); <code>TrainBalance</code> drives the
twin with varying boundaries and correction flows and integrates what crosses
its boundary, so that a test can check the train's mass and dry-solids
balances.</p>
</html>"));
end Validation;
