within TrackingBox.Evaporation.Functions;
function splus "Smooth positive part: (z + sqrt(z^2 + eps^2))/2"
  input Real z "Argument";
  input Real eps = 0.01 "Smoothing width, in the unit of z";
  output Real y "Approximately max(z, 0); y(0) = eps/2, y > 0 everywhere";
algorithm
  y := 0.5*(z + sqrt(z*z + eps*eps));
  annotation (smoothOrder=100, Documentation(info="<html>
<p>C-infinity replacement for <code>max(z, 0)</code>; the error is below
<code>eps/2</code> and vanishes like <code>eps&sup2;/(4|z|)</code> far from zero.</p>
</html>"));
end splus;
