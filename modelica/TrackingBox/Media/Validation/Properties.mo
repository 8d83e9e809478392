within TrackingBox.Media.Validation;
model Properties "Every media function evaluated at the point given by the inputs"
  extends TrackingBox.Icons.Example;
  input TrackingBox.Units.Temperature T(start=373.15) "Temperature";
  input TrackingBox.Units.Pressure p(start=101325) "Pressure";
  input TrackingBox.Units.Fraction x(start=0.5) "Dry-solids mass fraction of the liquor";
  output TrackingBox.Units.Pressure pSat "Saturation pressure at T";
  output TrackingBox.Units.Temperature TSat "Saturation temperature at p";
  output TrackingBox.Units.Temperature TSatOfpSat "TSat(pSat(T)): should give T back";
  output Real hLiquid(unit="J/kg") "Saturated-liquid enthalpy at T";
  output Real hVapour(unit="J/kg") "Saturated-vapour enthalpy at T";
  output Real hfg(unit="J/kg") "Latent heat at T";
  output TrackingBox.Units.TemperatureDifference bpr "Boiling-point rise of the liquor at (x, p)";
  output TrackingBox.Units.SpecificHeatCapacity cpLiquor "Specific heat capacity of the liquor at (x, T)";
  output Real hLiquor(unit="J/kg") "Specific enthalpy of the liquor at (x, T)";
  output TrackingBox.Units.Density rhoLiquor "Density of the liquor at (x, T), default k = 649 kg/m3";
  output TrackingBox.Units.Density rhoLiquor694 "Density of the liquor at (x, T) with k = 694 kg/m3";
equation
  pSat = TrackingBox.Media.Water.Saturation.pSat(T);
  TSat = TrackingBox.Media.Water.Saturation.TSat(p);
  TSatOfpSat = TrackingBox.Media.Water.Saturation.TSat(pSat);
  hLiquid = TrackingBox.Media.Water.Saturation.hLiquid(T);
  hVapour = TrackingBox.Media.Water.Saturation.hVapour(T);
  hfg = TrackingBox.Media.Water.Saturation.hfg(T);
  bpr = TrackingBox.Media.BlackLiquor.boilingPointRise(x, p);
  cpLiquor = TrackingBox.Media.BlackLiquor.cp(x, T);
  hLiquor = TrackingBox.Media.BlackLiquor.specificEnthalpy(x, T);
  rhoLiquor = TrackingBox.Media.BlackLiquor.density(x, T);
  rhoLiquor694 = TrackingBox.Media.BlackLiquor.density(x, T, k=694);
  annotation (experiment(StopTime=1), Documentation(info="<html>
<p>No states: each output is one media function of the inputs
<code>T</code>, <code>p</code> and <code>x</code>, so a table of input
points gives a table of property values (the tests drive it with
IAPWS-IF97 points and the published black-liquor points). Run alone it
evaluates at 100 degC, 101.325 kPa and 50 % dry solids.</p>
</html>"));
end Properties;
