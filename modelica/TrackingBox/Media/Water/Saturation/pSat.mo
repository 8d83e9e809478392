within TrackingBox.Media.Water.Saturation;
function pSat "Saturation pressure of water as a function of temperature (IAPWS-IF97 region 4)"
  input TrackingBox.Units.Temperature T "Temperature";
  output TrackingBox.Units.Pressure p "Saturation pressure";
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
  Real theta "Transformed temperature (T in K)";
  Real A;
  Real B;
  Real C;
algorithm
  theta := T + n9/(T - n10);
  A := theta^2 + n1*theta + n2;
  B := n3*theta^2 + n4*theta + n5;
  C := n6*theta^2 + n7*theta + n8;
  p := 1e6*(2*C/(-B + sqrt(B^2 - 4*A*C)))^4;
  annotation (Documentation(info="<html>
<p>The saturation equation of IAPWS-IF97 (region 4) is a quadratic in
<code>beta = (p/1 MPa)^(1/4)</code> whose coefficients are quadratics in the
transformed temperature <code>theta = T + n9/(T - n10)</code>; this function
takes its positive root. Valid 273.15..647.096 K; smooth, no events.
Inverse: <a href=\"modelica://TrackingBox.Media.Water.Saturation.TSat\">TSat</a>.</p>
</html>"));
end pSat;
