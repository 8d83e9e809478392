within TrackingBox.Benches.HeatExchanger.Hidden;
model SensorDrift "Heat-exchanger plant whose hot-outlet thermometer drifts"
  extends TrackingBox.Benches.HeatExchanger.Plant;
  parameter TrackingBox.Units.Time tStart = 3600 "Start of the drift";
  parameter TrackingBox.Units.TemperatureDifference drift = 1.5 "Final error of the reading";
  parameter TrackingBox.Units.Time tau = 20000 "Time constant of the drift";
  TrackingBox.Interfaces.RealOutput ThOut_sensor(unit="K") "Reading of the hot-outlet thermometer TI-102"
    annotation (Placement(transformation(origin={0,110}, extent={{-10,-10},{10,10}}, rotation=90)));
equation
  ThOut_sensor = ThOut + drift*(1 - exp(-noEvent(max(time - tStart, 0))/tau));
  annotation (Documentation(info="<html>
<p>The reading of TI-102 departs from the true hot outlet temperature by
<code>drift&middot;(1 - exp(-(t - tStart)/tau))</code>: about 1.1 K at the end of
an 8-hour case. The process is the plain plant.</p>
</html>"));
end SensorDrift;
