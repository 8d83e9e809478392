within TrackingBox.Media.Water.Saturation;
function hfg "Latent heat of vaporisation of water, 20..200 degC"
  input TrackingBox.Units.Temperature T "Saturation temperature";
  output Real r(unit="J/kg") "Specific enthalpy of vaporisation";
algorithm
  r := hVapour(T) - hLiquid(T);
  annotation (Documentation(info="<html>
<p>Difference of the saturated vapour and liquid enthalpies
(<code>hVapour - hLiquid</code>), so the three stay consistent; within
11 J/kg of IAPWS-IF97 between 20 and 200 degC.</p>
</html>"));
end hfg;
