within TrackingBox.Benches.Evaporator.BaseClasses;
model TrackedProductPump "Liquor pump with the bench's tracking bounds on dp0 (2..5 bar) and VMax (1.5..4.5 l/s)"
  extends TrackingBox.Evaporation.LiquorPump(dp0(min=2e5, max=5e5), VMax(min=1.5e-3, max=4.5e-3));
  annotation (Documentation(info="<html>
<p><code>Evaporation.LiquorPump</code> unchanged, with the ranges the bench
allows the product pump's curve: shut-off pressure rise <code>dp0</code>
2..5 bar (design 4 bar) and maximum volume flow <code>VMax</code>
1.5..4.5 l/s (design 3 l/s). Declared in a class so that <code>Plant</code>,
which sets <code>pump(dp0=3.7e5, VMax=2.8e-3)</code> through its
<code>extends</code> clause, keeps the bounds (see
<code>TrackedInletValve</code>).</p>
</html>"));
end TrackedProductPump;
