within TrackingBox.Media.BlackLiquor;
function boilingPointRise "Boiling-point rise of black liquor over water at the same pressure"
  input TrackingBox.Units.Fraction x "Dry-solids mass fraction (0..1)";
  input TrackingBox.Units.Pressure p "Pressure";
  output TrackingBox.Units.TemperatureDifference bpr "Boiling-point rise";
protected
  Real xPos(unit="1") "Smooth positive part of x, for the power 1.5";
  TrackingBox.Units.TemperatureDifference bprAtm "Boiling-point rise at atmospheric pressure";
algorithm
  xPos := 0.5*(x + sqrt(x^2 + 1e-8));
  bprAtm := 6.173*x - 7.48*xPos*sqrt(xPos) + 32.747*x^2;
  bpr := bprAtm*(1 + 0.6*(TrackingBox.Media.Water.Saturation.TSat(p) - 373.16)/100);
  annotation (Documentation(info="<html>
<p>Frederick-type correlation: <code>BPR_atm = 6.173 x - 7.48 x^1.5 + 32.747 x^2</code>
(K), multiplied by <code>1 + 0.6 (TSat(p) - 373.16 K)/100 K</code> for the
pressure. Gives 1.2, 3.6, 8.6, 13.9 and 20.5 K at x = 0.15, 0.30, 0.50, 0.65,
0.80 near atmospheric pressure, 0.72 times that at 15 kPa and 1.20 times at
300 kPa. The power <code>x^1.5</code> is taken of the smooth positive part
<code>(x + sqrt(x^2 + 1e-8))/2</code> (differs from x by less than 1e-7 for
x above 0.02) so a solver trying a slightly negative x gets a finite value.</p>
</html>"));
end boilingPointRise;
