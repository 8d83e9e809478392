within TrackingBox.Benches.HeatProduction.Hidden;
model SensorDrift "Heat-production plant whose T100 thermometer TI-100 drifts"
  extends TrackingBox.Benches.HeatProduction.Plant;
  parameter TrackingBox.Units.Time tStart = 14400 "Start of the drift";
  parameter TrackingBox.Units.TemperatureDifference drift = -2.0 "Final error of the reading";
  parameter TrackingBox.Units.Time tau = 50000 "Time constant of the drift";
  TrackingBox.Interfaces.RealOutput TI_100_sensor(unit="K") "Reading of the T100 thermometer TI-100"
    annotation (Placement(transformation(origin={0,110}, extent={{-10,-10},{10,10}}, rotation=90)));
equation
  TI_100_sensor = TI_100 + drift*(1 - exp(-noEvent(max(time - tStart, 0))/tau));
  annotation (Documentation(info="<html>
<p>The reading of TI-100 departs from the tank temperature by
<code>drift&middot;(1 - exp(-(t - tStart)/tau))</code>: -1.6 K at the end of a
24-hour case. The controller TIC100 uses the true temperature (its own
sensor), so only the reading is wrong.</p>
</html>"));
end SensorDrift;
