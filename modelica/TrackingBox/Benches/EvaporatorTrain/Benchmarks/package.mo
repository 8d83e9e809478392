within TrackingBox.Benches.EvaporatorTrain;
package Benchmarks "The 7-effect plant and twin through one day (scripts/bench_compile: compile time and one simulated day)"
  annotation (Documentation(info="<html>
<p>Not validation models: they run a whole day of the default 7-effect train
and are kept out of the test suite's comparison with rumoca's own simulation
(which runs every <code>Validation</code> model); <code>scripts/bench_compile</code>
times their compilation and one simulated day.</p>
</html>"));
end Benchmarks;
