model ThermalWall "A wall between two measured air temperatures: two thermal resistances and a heat capacity, built from Modelica.Thermal.HeatTransfer"
  parameter Modelica.Units.SI.ThermalResistance R1(min=1e-4, max=1) = 0.02 "Inside film and inner layer";
  parameter Modelica.Units.SI.ThermalResistance R2(min=1e-4, max=1) = 0.05 "Outer layer and outside film";
  parameter Modelica.Units.SI.HeatCapacity C(min=1e3, max=1e8) = 2e5 "Heat capacity of the wall";
  parameter Modelica.Units.SI.Temperature T_wall_start = 288.15 "Initial wall temperature";
  Modelica.Blocks.Interfaces.RealInput T_inside(unit="K", start=293.15) "Measured inside air temperature";
  Modelica.Blocks.Interfaces.RealInput T_outside(unit="K", start=278.15) "Measured outside air temperature";
  Modelica.Blocks.Interfaces.RealOutput T_wall(unit="K") "Temperature of the wall's core (the measured output)";
  Modelica.Blocks.Interfaces.RealOutput Q_inside(unit="W") "Heat flow from the inside air into the wall (not measured)";
  Modelica.Thermal.HeatTransfer.Sources.PrescribedTemperature inside "Inside air";
  Modelica.Thermal.HeatTransfer.Sources.PrescribedTemperature outside "Outside air";
  Modelica.Thermal.HeatTransfer.Components.ThermalResistor r1(R=R1) "Inner resistance";
  Modelica.Thermal.HeatTransfer.Components.ThermalResistor r2(R=R2) "Outer resistance";
  Modelica.Thermal.HeatTransfer.Components.HeatCapacitor wall(C=C, T(start=T_wall_start, fixed=true)) "Wall";
  Modelica.Thermal.HeatTransfer.Sensors.TemperatureSensor sensor "Thermocouple in the wall";
equation
  connect(T_inside, inside.T);
  connect(T_outside, outside.T);
  connect(inside.port, r1.port_a);
  connect(r1.port_b, wall.port);
  connect(wall.port, r2.port_a);
  connect(r2.port_b, outside.port);
  connect(wall.port, sensor.port);
  connect(sensor.T, T_wall);
  Q_inside = r1.Q_flow;
  annotation (experiment(StopTime=172800, Tolerance=1e-6), Documentation(info="<html>
<p>The identifiability case of <code>trackingbox identify</code>: seen through the wall's
temperature alone, the data determine only the time constants <code>R1*C</code> and
<code>R2*C</code>, not <code>R1</code>, <code>R2</code> and <code>C</code> themselves (multiplying
both resistances by any factor and dividing the capacity by it leaves <code>T_wall</code>
unchanged). The heat flow <code>Q_inside</code> would separate them.</p>
</html>"));
end ThermalWall;
