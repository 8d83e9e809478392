within TrackingBox.Media.Water.Saturation;
function hLiquid "Specific enthalpy of saturated liquid water, 20..200 degC"
  input TrackingBox.Units.Temperature T "Temperature";
  output Real h(unit="J/kg") "Specific enthalpy of the saturated liquid";
protected
  Real tau(unit="1") "(T - 273.15 K)/100 K";
algorithm
  tau := (T - 273.15)/100;
  h := 67.8851153 + tau*(420264.779 + tau*(-6193.75877 + tau*(6210.01567
    + tau*(-1679.4336 + tau*429.994756))));
  annotation (Documentation(info="<html>
<p>Quintic polynomial in <code>(T - 273.15 K)/100 K</code>, least-squares
fitted to IAPWS-IF97 saturated-liquid enthalpies at 0.25 K spacing between
20 and 200 degC: within 2 J/kg there. IAPWS reference state (the liquid's
internal energy and entropy are zero at the triple point).</p>
</html>"));
end hLiquid;
