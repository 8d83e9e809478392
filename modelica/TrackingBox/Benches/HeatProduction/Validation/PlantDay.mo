within TrackingBox.Benches.HeatProduction.Validation;
model PlantDay "Plant over one day of varying heat demand"
  extends TrackingBox.Icons.Example;
  TrackingBox.Benches.HeatProduction.Plant bench "Model under test";
protected
  constant Real pi = 3.141592653589793 "Circle constant";
equation
  bench.mCold_flow = 0.06 - 0.015*cos(2*pi*time/86400) + 0.01*TrackingBox.Blocks.smoothStep(time, 3600, 300)
    - 0.015*TrackingBox.Blocks.smoothStep(time, 50000, 600);
  bench.TColdIn = 313.15 + 2*sin(2*pi*time/43200);
  bench.TColdOut_set = 338.15;
  bench.THU300_set = 363.15;
  bench.TPre_set = 328.15;
  bench.TMakeUp = 288.15;
  bench.TAmb = 293.15 + 5*sin(2*pi*(time - 30000)/86400);
  bench.holdControllers = 0;
  annotation (experiment(StopTime=86400, Tolerance=1e-6), Documentation(info="<html>
<p>Heat demand: cold-stream flow 0.045..0.085 kg/s (daily cosine, +0.01 kg/s at
1 h, -0.015 kg/s at 13.9 h), inlet 40 degC &plusmn; 2 K; setpoints constant;
ambient 20 degC &plusmn; 5 K. Controllers in automatic.</p>
</html>"));
end PlantDay;
