within TrackingBox.Media.Water.Saturation;
function TSat "Saturation temperature of water as a function of pressure (IAPWS-IF97 region 4)"
  input TrackingBox.Units.Pressure p "Pressure";
  output TrackingBox.Units.Temperature T "Saturation temperature";
protected
  constant Real n1 = 0.11670521452767e4;
  constant Real n2 = -0.72421316598842e6;
  constant Real n3 = -0.17073846940092e2;
  constant Real n4 = 0.12020824702470e5;
  constant Real n5 = -0.32325550322333e7;
  constant Real n6 = 0.14915108613530e2;
  constant Real n7 = -0.48232657361591e4;
  constant Real n8 = 0.40511340542057e6;
  constant Real n9 = -0.23855557567849;
  constant Real n10 = 0.65017534844798e3;
  Real beta "Transformed pressure, (p/1 MPa)^(1/4)";
  Real E;
  Real F;
  Real G;
  Real D;
algorithm
  beta := (p/1e6)^0.25;
  E := beta^2 + n3*beta + n6;
  F := n1*beta^2 + n4*beta + n7;
  G := n2*beta^2 + n5*beta + n8;
  D := 2*G/(-F - sqrt(F^2 - 4*E*G));
  T := (n10 + D - sqrt((n10 + D)^2 - 4*(n9 + n10*D)))/2;
  annotation (Documentation(info="<html>
<p>The IAPWS-IF97 saturation equation (region 4) read as a quadratic in the
transformed temperature, solved explicitly for the temperature: the
backward equation of IF97. Valid 611.213 Pa..22.064 MPa (pressures must be
positive); smooth, no events. Inverse:
<a href=\"modelica://TrackingBox.Media.Water.Saturation.pSat\">pSat</a>.</p>
</html>"));
end TSat;
