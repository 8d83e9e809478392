within TrackingBox.Media.Water.Saturation;
function hVapour "Specific enthalpy of saturated steam, 20..200 degC"
  input TrackingBox.Units.Temperature T "Temperature";
  output Real h(unit="J/kg") "Specific enthalpy of the saturated vapour";
protected
  Real tau(unit="1") "(T - 273.15 K)/100 K";
algorithm
  tau := (T - 273.15)/100;
  h := 2500695.88 + tau*(185718.343 + tau*(-10727.7362 + tau*(8308.72633
    + tau*(-11073.6152 + tau*(3008.38914 + tau*(-354.855822))))));
  annotation (Documentation(info="<html>
<p>Sixth-degree polynomial in <code>(T - 273.15 K)/100 K</code>,
least-squares fitted to IAPWS-IF97 saturated-vapour enthalpies at 0.25 K
spacing between 20 and 200 degC: within 10 J/kg there. IAPWS reference
state, as <code>hLiquid</code>.</p>
</html>"));
end hVapour;
