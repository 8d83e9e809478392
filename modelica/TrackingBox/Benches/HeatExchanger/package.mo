within TrackingBox.Benches;
package HeatExchanger "Test bench 1: counter-flow water/water heat exchanger"
  annotation (Documentation(info="<html>
<p>Two water streams in a counter-flow heat exchanger (10 cells per side).
Inputs: inlet temperatures and mass flows of both streams; outputs: both
outlet temperatures. The tracking parameter is <code>hx.kht</code>
(plant 910, twin 1000 W/(m2.K), bounds 500..1500). At the nominal point
(hot 1 kg/s at 90 degC, cold 2 kg/s at 10 degC) the hot outlet is about
2.2 K warmer in the plant (46.5 vs 48.7 degC) than in the twin; residence times are 2 min (hot)
and 1 min (cold).</p>
</html>"));
end HeatExchanger;
