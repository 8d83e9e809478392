within TrackingBox.Benches.Evaporator.BaseClasses;
model TrackedInletValve "Liquor valve with the bench's tracking bounds on KvMax (8..26 m3/h), for the feed"
  extends TrackingBox.Evaporation.LiquorValve(KvMax(min=8, max=26));
  annotation (Documentation(info="<html>
<p><code>Evaporation.LiquorValve</code> unchanged, with the range the bench
allows the inlet valve's flow coefficient <code>KvMax</code>: 8..26 m3/h
around the design value 17 m3/h. Declared in a class so that
<code>Plant</code>, which sets <code>inletValve(KvMax=15.5)</code> through its
<code>extends</code> clause, keeps the bounds: rumoca 0.10.2 replaces a
component declaration's <code>KvMax(min=..., max=...)</code> with the
modification given through <code>extends</code> instead of merging them.</p>
</html>"));
end TrackedInletValve;
