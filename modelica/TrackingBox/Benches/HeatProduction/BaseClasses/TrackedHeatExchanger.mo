within TrackingBox.Benches.HeatProduction.BaseClasses;
model TrackedHeatExchanger "Counter-flow heat exchanger with the bench's tracking bounds on kht (850..1150 W/(m2.K))"
  extends TrackingBox.Fluid.HeatExchanger(kht(min=850, max=1150));
  annotation (Documentation(info="<html>
<p><code>Fluid.HeatExchanger</code> unchanged, with the range the bench
allows its heat-transfer coefficient <code>kht</code>: 850..1150 W/(m2.K),
the twin's design value 1000 &plusmn; 15 %. Used for <code>HEX300</code>.
Declared in a class so that <code>Plant</code>, which sets
<code>HEX300(kht=920)</code> through its <code>extends</code> clause, keeps
the bounds (see <code>TrackedHeatingUnit</code>).</p>
</html>"));
end TrackedHeatExchanger;
