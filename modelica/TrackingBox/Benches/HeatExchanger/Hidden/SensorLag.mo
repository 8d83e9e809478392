within TrackingBox.Benches.HeatExchanger.Hidden;
model SensorLag "Heat-exchanger plant whose cold-outlet thermometer lags (thermowell)"
  extends TrackingBox.Benches.HeatExchanger.Plant;
  parameter TrackingBox.Units.Time tau1 = 90 "Time constant of the thermowell";
  parameter TrackingBox.Units.Time tau2 = 30 "Time constant of the probe in the well";
  TrackingBox.Units.Temperature TWell(start=308.15, fixed=true) "Thermowell temperature";
  TrackingBox.Interfaces.RealOutput TcOut_sensor(start=308.15, fixed=true, unit="K") "Reading of the cold-outlet thermometer TI-202"
    annotation (Placement(transformation(origin={0,110}, extent={{-10,-10},{10,10}}, rotation=90)));
equation
  tau1*der(TWell) = TcOut - TWell;
  tau2*der(TcOut_sensor) = TWell - TcOut_sensor;
  annotation (Documentation(info="<html>
<p>The reading of TI-202 follows the cold outlet temperature through two
first-order stages in series (well 90 s, probe 30 s): a second-order lag. The
process is the plain plant.</p>
</html>"));
end SensorLag;
