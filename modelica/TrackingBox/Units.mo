within TrackingBox;
package Units "SI types used in the library"
  type Temperature = Real (final quantity="ThermodynamicTemperature", final unit="K", displayUnit="degC", min=0, nominal=300) "Absolute temperature";
  type TemperatureDifference = Real (final quantity="ThermodynamicTemperature", final unit="K") "Temperature difference";
  type Pressure = Real (final quantity="Pressure", final unit="Pa", displayUnit="bar", nominal=1e5) "Absolute pressure";
  type PressureDifference = Real (final quantity="Pressure", final unit="Pa", nominal=1e4) "Pressure difference";
  type MassFlowRate = Real (final quantity="MassFlowRate", final unit="kg/s") "Mass flow rate";
  type VolumeFlowRate = Real (final quantity="VolumeFlowRate", final unit="m3/s") "Volume flow rate";
  type Mass = Real (final quantity="Mass", final unit="kg", min=0) "Mass";
  type Volume = Real (final quantity="Volume", final unit="m3", min=0) "Volume";
  type Area = Real (final quantity="Area", final unit="m2", min=0) "Area";
  type Length = Real (final quantity="Length", final unit="m") "Length";
  type Height = Real (final quantity="Length", final unit="m") "Height or level";
  type Density = Real (final quantity="Density", final unit="kg/m3", min=0, nominal=1000) "Density";
  type SpecificHeatCapacity = Real (final quantity="SpecificHeatCapacity", final unit="J/(kg.K)", min=0, nominal=4000) "Specific heat capacity";
  type HeatFlowRate = Real (final quantity="Power", final unit="W") "Heat flow rate";
  type Power = Real (final quantity="Power", final unit="W") "Power";
  type ThermalConductance = Real (final quantity="ThermalConductance", final unit="W/K") "Thermal conductance";
  type CoefficientOfHeatTransfer = Real (final quantity="CoefficientOfHeatTransfer", final unit="W/(m2.K)", min=0) "Heat-transfer coefficient";
  type Time = Real (final quantity="Time", final unit="s") "Time";
  type Acceleration = Real (final quantity="Acceleration", final unit="m/s2") "Acceleration";
  type Fraction = Real (final unit="1") "Dimensionless fraction, typically 0..1";
  type ValveCoefficient = Real (final unit="m3/h", min=0) "Valve flow coefficient Kv: flow in m3/h at 1 bar pressure drop";
  type Factor = Real (final unit="1", min=0) "Dimensionless coefficient or factor, not negative";
  type PressureRise = Real (final quantity="Pressure", final unit="Pa", min=0, nominal=1e4) "Pressure rise of a pump, not negative";
  type PositiveVolumeFlowRate = Real (final quantity="VolumeFlowRate", final unit="m3/s", min=1e-9) "Volume flow rate that scales a characteristic, positive";
  type FractionRate = Real (final unit="1/s") "Rate of change of a dimensionless fraction";
  annotation (Documentation(info="<html>
<p>Real types with SI units, in the style of <code>Modelica.Units.SI</code>.
Temperatures are absolute (K); pressures are absolute (Pa).</p>
</html>"));
end Units;
