within TrackingBox.Benches.HeatProduction;
package Validation "Plant and twin driven by time functions"
  annotation (Documentation(info="<html>
<p><code>PlantDay</code> and <code>TwinDay</code> run plant and twin through
one day of varying heat demand (the cold stream's flow with a daily cycle and
two steps, its inlet temperature with a half-day cycle, the ambient
temperature with a daily cycle), setpoints constant and all controllers in
automatic. <code>tests/test_bench_models.py</code> compiles each and compares
it with rumoca's own simulation of the same source.</p>
</html>"));
end Validation;
