within TrackingBox.Blocks;
function smoothStep "Step from 0 to 1 with a smooth (cubic) transition, for test excitations"
  input Real t "Independent variable, usually time";
  input Real tStart "Start of the transition";
  input Real duration(min=1e-9) "Duration of the transition";
  output Real y "0 before tStart, 1 after tStart + duration";
protected
  Real x "Normalised position in the transition";
algorithm
  x := min(max((t - tStart)/duration, 0), 1);
  y := x*x*(3 - 2*x);
  annotation (Documentation(info="<html>
<p><code>y = x&sup2;(3 - 2x)</code> with <code>x</code> the clipped normalised time:
continuously differentiable, so excitations built from it cause no events.</p>
</html>"));
end smoothStep;
