within TrackingBox.Benches.HeatExchanger;
package Validation "Plant and twin driven by time functions"
  annotation (Documentation(info="<html>
<p><code>PlantExcitation</code> and <code>TwinExcitation</code> drive plant and
twin with the same signals: steps in both flows and in the cold inlet
temperature, a sine on the hot inlet temperature, built from
<code>Blocks.smoothStep</code> so that they cause no events. With one input
history the two models differ only by <code>hx.kht</code> (910 against
1000 W/(m2.K)). <code>tests/test_bench_models.py</code> compiles each and
compares it with rumoca's own simulation of the same source.</p>
</html>"));
end Validation;
