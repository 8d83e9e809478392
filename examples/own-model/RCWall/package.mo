within;
package RCWall "A building wall as two thermal resistances and a heat capacity, built from the Modelica Standard Library"
  extends Modelica.Icons.Package;

  model Wall "Inside air, the wall's mass, outside air: the wall temperature from both air temperatures"
    parameter Modelica.Units.SI.ThermalResistance R1 = 0.01 "Inside air to the wall's mass";
    parameter Modelica.Units.SI.ThermalResistance R2 = 0.04 "The wall's mass to the outside air";
    parameter Modelica.Units.SI.HeatCapacity C = 2e6 "Heat capacity of the wall";
    Modelica.Blocks.Interfaces.RealInput T_in(unit = "K", displayUnit = "degC") "Inside air temperature"
      annotation (Placement(transformation(extent = {{-140, 20}, {-100, 60}})));
    Modelica.Blocks.Interfaces.RealInput T_out(unit = "K", displayUnit = "degC") "Outside air temperature"
      annotation (Placement(transformation(extent = {{-140, -60}, {-100, -20}})));
    Modelica.Blocks.Interfaces.RealOutput T_wall(unit = "K", displayUnit = "degC") "Temperature of the wall's mass"
      annotation (Placement(transformation(extent = {{100, -10}, {120, 10}})));
    Modelica.Thermal.HeatTransfer.Sources.PrescribedTemperature inside
      annotation (Placement(transformation(extent = {{-80, 30}, {-60, 50}})));
    Modelica.Thermal.HeatTransfer.Sources.PrescribedTemperature outside
      annotation (Placement(transformation(extent = {{-80, -50}, {-60, -30}})));
    Modelica.Thermal.HeatTransfer.Components.ThermalResistor thermalResistor1(R = R1)
      annotation (Placement(transformation(extent = {{-40, 30}, {-20, 50}})));
    Modelica.Thermal.HeatTransfer.Components.ThermalResistor thermalResistor2(R = R2)
      annotation (Placement(transformation(extent = {{-40, -50}, {-20, -30}})));
    Modelica.Thermal.HeatTransfer.Components.HeatCapacitor wall(C = C, T(start = 288.15, fixed = true))
      annotation (Placement(transformation(extent = {{0, 10}, {20, 30}})));
    Modelica.Thermal.HeatTransfer.Sensors.TemperatureSensor sensor
      annotation (Placement(transformation(extent = {{40, -10}, {60, 10}})));
  equation
    connect(T_in, inside.T)
      annotation (Line(points = {{-120, 40}, {-82, 40}}, color = {0, 0, 127}));
    connect(T_out, outside.T)
      annotation (Line(points = {{-120, -40}, {-82, -40}}, color = {0, 0, 127}));
    connect(inside.port, thermalResistor1.port_a)
      annotation (Line(points = {{-60, 40}, {-40, 40}}, color = {191, 0, 0}));
    connect(outside.port, thermalResistor2.port_a)
      annotation (Line(points = {{-60, -40}, {-40, -40}}, color = {191, 0, 0}));
    connect(thermalResistor1.port_b, wall.port)
      annotation (Line(points = {{-20, 40}, {10, 40}, {10, 10}}, color = {191, 0, 0}));
    connect(thermalResistor2.port_b, wall.port)
      annotation (Line(points = {{-20, -40}, {10, -40}, {10, 10}}, color = {191, 0, 0}));
    connect(wall.port, sensor.port)
      annotation (Line(points = {{10, 10}, {10, 0}, {40, 0}}, color = {191, 0, 0}));
    connect(sensor.T, T_wall)
      annotation (Line(points = {{61, 0}, {110, 0}}, color = {0, 0, 127}));
    annotation (experiment(StopTime = 259200, Interval = 300));
  end Wall;

  annotation (uses(Modelica(version = "4.0.0")), version = "1.0.0");
end RCWall;
