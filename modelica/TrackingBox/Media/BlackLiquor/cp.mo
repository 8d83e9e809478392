within TrackingBox.Media.BlackLiquor;
function cp "Specific heat capacity of black liquor"
  input TrackingBox.Units.Fraction x "Dry-solids mass fraction (0..1)";
  input TrackingBox.Units.Temperature T "Temperature";
  output TrackingBox.Units.SpecificHeatCapacity cp "Specific heat capacity";
protected
  Real t(unit="degC") "Celsius temperature";
algorithm
  t := T - 273.15;
  cp := 1000*(4.216*(1 - x) + (1.675 + 3.31e-3*t)*x + (4.87 - 0.020*t)*(1 - x)*x^3);
  annotation (Documentation(info="<html>
<p><code>cp = 4.216 (1 - x) + (1.675 + 3.31 t/1000) x + (4.87 - 20 t/1000)(1 - x) x^3</code>
kJ/(kg.K), <code>t</code> in degC: water, dry solids and an excess term.
Gives 3.88, 3.29 and 2.76 kJ/(kg.K) at (x, t) = (0.15, 60 degC),
(0.5, 100 degC), (0.8, 130 degC).</p>
</html>"));
end cp;
