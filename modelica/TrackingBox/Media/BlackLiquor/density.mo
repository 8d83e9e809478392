within TrackingBox.Media.BlackLiquor;
function density "Density of black liquor"
  input TrackingBox.Units.Fraction x "Dry-solids mass fraction (0..1)";
  input TrackingBox.Units.Temperature T "Temperature";
  input Real k(unit="kg/m3") = 649 "Density increase per unit dry-solids fraction";
  output TrackingBox.Units.Density rho "Density";
protected
  Real t(unit="degC") "Celsius temperature";
algorithm
  t := T - 273.15;
  rho := (997 + k*x)*(1.008 - 0.237e-3*t - 1.94e-6*t^2);
  annotation (Documentation(info="<html>
<p><code>rho = (997 + k x)(1.008 - 0.237 t/1000 - 1.94 (t/1000)^2)</code> kg/m3,
<code>t</code> in degC. The default <code>k = 649</code> kg/m3 is one published
value, 694 another: at x = 0.75 they give 1484 and 1518 kg/m3 where the
temperature factor is 1 (near 27.5 degC), about 1412 and 1444 kg/m3 at
120 degC. Inferring the dry solids from a density with the wrong k is off by
about 5 %DS at 75 %.</p>
</html>"));
end density;
