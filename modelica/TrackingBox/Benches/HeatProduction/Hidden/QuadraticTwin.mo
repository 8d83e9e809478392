within TrackingBox.Benches.HeatProduction.Hidden;
model QuadraticTwin "Heat-production twin with the plant's quadratic curves: the twin the hidden-effect suite diagnoses against"
  extends TrackingBox.Benches.HeatProduction.Twin(quadratic=true);
  annotation (Documentation(info="<html>
<p>The bench's twin (<code>Twin</code>: initial parameter values of the method
notes, tank correction flows) with the plant's quadratic pipe and pump curves.
The source's twin has linear curves; against the plain plant they leave a
residual of 10-30 noise standard deviations on most tags, which is itself a
missing effect outside the diagnosis library. The hidden-effect cases of this
bench hide one effect each; they are diagnosed against this twin, so that the
effect is the only thing the twin lacks beyond parameter values.</p>
</html>"));
end QuadraticTwin;
