within TrackingBox.Evaporation.Functions;
function regRoot "Regularised signed square root dp/(dp^2 + delta^2)^(1/4)"
  input Real dp "Argument (for example a pressure difference, Pa)";
  input Real delta = 100 "Below about this magnitude the function is linear";
  output Real y "Approximately sign(dp)*sqrt(|dp|)";
algorithm
  y := dp/sqrt(sqrt(dp*dp + delta*delta));
  annotation (smoothOrder=100, Documentation(info="<html>
<p>The regularisation of the Modelica Standard Library's
<code>Fluid.Utilities.regRoot</code>: odd, smooth, finite slope
<code>1/sqrt(delta)</code> at zero.</p>
</html>"));
end regRoot;
