within TrackingBox.Benches.Evaporator.BaseClasses;
model TrackedOutletValve "Liquor valve with the bench's tracking bounds on KvMax (3.5..10.5 m3/h), for the effect's outlet"
  extends TrackingBox.Evaporation.LiquorValve(KvMax(min=3.5, max=10.5));
  annotation (Documentation(info="<html>
<p><code>Evaporation.LiquorValve</code> unchanged, with the range the bench
allows the outlet valve's flow coefficient <code>KvMax</code>: 3.5..10.5 m3/h,
the design value 7 m3/h &plusmn; 50 %. Declared in a class so that
<code>Plant</code>, which sets <code>outletValve(KvMax=7.6)</code> through its
<code>extends</code> clause, keeps the bounds (see
<code>TrackedInletValve</code>).</p>
</html>"));
end TrackedOutletValve;
