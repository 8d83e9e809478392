within TrackingBox.Media.BlackLiquor;
function specificEnthalpy "Specific enthalpy of black liquor, zero at 0 degC"
  input TrackingBox.Units.Fraction x "Dry-solids mass fraction (0..1)";
  input TrackingBox.Units.Temperature T "Temperature";
  output Real h(unit="J/kg") "Specific enthalpy (h = 0 at 273.15 K)";
protected
  Real t(unit="degC") "Celsius temperature";
  Real a(unit="J/(kg.K)") "Part of cp independent of t";
  Real b(unit="J/(kg.K2)") "Coefficient of t in cp";
algorithm
  t := T - 273.15;
  a := 1000*(4.216*(1 - x) + 1.675*x + 4.87*(1 - x)*x^3);
  b := 1000*(3.31e-3*x - 0.020*(1 - x)*x^3);
  h := a*t + 0.5*b*t^2;
  annotation (Documentation(info="<html>
<p>The integral of <a href=\"modelica://TrackingBox.Media.BlackLiquor.cp\">cp</a>
from 273.15 K to <code>T</code> at fixed <code>x</code>, done analytically:
<code>cp = a(x) + b(x) t</code> gives <code>h = a t + b t^2/2</code>, so
<code>dh/dT = cp</code> exactly. Reference: <code>h = 0</code> at 0 degC
for every x (no heat of dilution, and no enthalpy of mixing water and
solids). For water (x = 0) this is within 2.5 kJ/kg of
<code>Water.Saturation.hLiquid</code> between 0 and 160 degC; a balance that mixes
liquor and water/steam enthalpies uses the two references consistently as
long as the water leaving the liquor is counted with <code>hVapour</code>
at the same temperature.</p>
</html>"));
end specificEnthalpy;
