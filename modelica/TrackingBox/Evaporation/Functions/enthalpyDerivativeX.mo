within TrackingBox.Evaporation.Functions;
function enthalpyDerivativeX "Partial derivative of the black-liquor specific enthalpy with respect to the dry-solids fraction"
  input TrackingBox.Units.Fraction x "Dry-solids mass fraction";
  input TrackingBox.Units.Temperature T "Temperature";
  output Real dhdx(unit="J/kg") "dh/dx at constant T";
protected
  Real t = T - 273.15 "Celsius temperature";
algorithm
  dhdx := -4216*t + 1675*t + 1.655*t*t + (4870*t - 10*t*t)*(3*x*x - 4*x*x*x);
  annotation (smoothOrder=100, Documentation(info="<html>
<p>The enthalpy of <code>Media.BlackLiquor.specificEnthalpy</code> is the
integral of the specific heat <code>cp(x, T)</code> of the evaporator notes
(section 1, in J/(kg.K): <code>4216(1-x) + (1675 + 3.31t)x + (4870 - 20t)(1-x)x&sup3;</code>)
from 0 &deg;C, so</p>
<pre>h = 4216(1-x)t + (1675t + 1.655t&sup2;)x + (4870t - 10t&sup2;)(1-x)x&sup3;</pre>
<p>and this function is its derivative in <code>x</code>. The vessels need it
to write the energy balance of <code>M&middot;h(x, T)</code> with
<code>T</code> as the state. The balance tests check it against the media
function (a wrong derivative shows as an energy balance that does not close).</p>
</html>"));
end enthalpyDerivativeX;
