within TrackingBox.Benches.HeatProduction.BaseClasses;
model TrackedHeatingUnit "Heating unit with the bench's tracking bounds on kht (945..1155 W/(m2.K))"
  extends TrackingBox.Fluid.HeatingUnit(kht(min=945, max=1155));
  annotation (Documentation(info="<html>
<p><code>Fluid.HeatingUnit</code> unchanged, with the range the bench allows
its heat-transfer coefficient <code>kht</code>: 945..1155 W/(m2.K), the
twin's design value 1050 &plusmn; 10 %. Used for <code>HU300</code>.</p>
<p>The bounds sit in a class of their own so that <code>Plant</code>, which
sets <code>HU300(kht=1000)</code> through its <code>extends</code> clause,
keeps them: rumoca 0.10.2 replaces a component declaration's
<code>kht(min=..., max=...)</code> with the modification given through
<code>extends</code> instead of merging the two (see
<code>PartialProcess</code>).</p>
</html>"));
end TrackedHeatingUnit;
