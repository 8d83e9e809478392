within TrackingBox.Benches.HeatExchanger.Validation;
model TwinExcitation "Twin with steps in both flows and inlet temperatures and a sine on the hot inlet"
  extends TrackingBox.Icons.Example;
  TrackingBox.Benches.HeatExchanger.Twin bench "Model under test";
equation
  bench.mHot_flow = 1.0 + 0.3*TrackingBox.Blocks.smoothStep(time, 1500, 60);
  bench.mCold_flow = 2.0 - 0.4*TrackingBox.Blocks.smoothStep(time, 3000, 60);
  bench.ThIn = 363.15 + 2*sin(2*3.141592653589793*time/1800);
  bench.TcIn = 283.15 + 3*TrackingBox.Blocks.smoothStep(time, 2300, 120);
  annotation (experiment(StopTime=4000, Tolerance=1e-6), Documentation(info="<html>
<p>Inputs: hot flow 1.0 &rarr; 1.3 kg/s at 1500 s, cold flow 2.0 &rarr; 1.6 kg/s at
3000 s, hot inlet 90 degC &plusmn; 2 K (period 1800 s), cold inlet 10 &rarr; 13 degC at
2300 s.</p>
</html>"));
end TwinExcitation;
