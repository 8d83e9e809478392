within TrackingBox.Benches.HeatProduction.BaseClasses;
model TrackedPipe "Pipe with the bench's tracking bounds on k (0.0001..0.01)"
  extends TrackingBox.Fluid.Pipe(k(min=0.0001, max=0.01));
  annotation (Documentation(info="<html>
<p><code>Fluid.Pipe</code> unchanged, with the range the bench allows its
pressure-drop coefficient <code>k</code>: 0.0001..0.01, that is a loss of
0.1..10 kPa at nominal flow with <code>dp_ref</code> = 1 MPa (design value
0.005, 5 kPa). Used for <code>Pipe100</code>, <code>Pipe101</code>,
<code>Pipe200</code> and <code>Pipe201</code>. Declared in a class so that
<code>Plant</code>, which sets <code>Pipe100(k=0.0065)</code> and the like
through its <code>extends</code> clause, keeps the bounds (see
<code>TrackedHeatingUnit</code>).</p>
</html>"));
end TrackedPipe;
