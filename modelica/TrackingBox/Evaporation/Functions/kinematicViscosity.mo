within TrackingBox.Evaporation.Functions;
function kinematicViscosity "Kinematic viscosity of black liquor (shape of the correlation in the evaporator notes)"
  input TrackingBox.Units.Fraction x "Dry-solids mass fraction";
  input TrackingBox.Units.Temperature T "Temperature";
  output Real nu(unit="m2/s") "Kinematic viscosity";
protected
  Real a "A(x)";
  Real b(unit="K3") "B(x)";
algorithm
  a := -2.4273 + 3.3532*x + 3.7654*x*x - 2.49*x*x*x;
  b := 6.1347e7 - 5.442e7*x + 2.1915e8*x*x + 1.7042e8*x*x*x;
  nu := 1e-6*exp(a + b/(T*T*T));
  annotation (smoothOrder=100, Documentation(info="<html>
<p><code>ln(&nu;/cSt) = A(x) + B(x)/T&sup3;</code> with the coefficients of the
evaporator notes (section 1). Its provenance is undocumented; it is used for the
shape only (the ratio in the liquor-side heat-transfer coefficient of
<code>Effect</code>).</p>
</html>"));
end kinematicViscosity;
