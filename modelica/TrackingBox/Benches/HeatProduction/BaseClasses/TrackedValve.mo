within TrackingBox.Benches.HeatProduction.BaseClasses;
model TrackedValve "Valve with the bench's tracking bounds on KvMax (0.9..1.1 m3/h)"
  extends TrackingBox.Fluid.Valve(KvMax(min=0.9, max=1.1));
  annotation (Documentation(info="<html>
<p><code>Fluid.Valve</code> unchanged, with the range the bench allows its
flow coefficient <code>KvMax</code>: 0.9..1.1 m3/h, the design value 1 m3/h
&plusmn; 10 %. Used for <code>V100</code> to <code>V400</code>. Declared in a
class so that <code>Plant</code>, which sets <code>V100(KvMax=0.96)</code> and
the like through its <code>extends</code> clause, keeps the bounds (see
<code>TrackedHeatingUnit</code>).</p>
</html>"));
end TrackedValve;
