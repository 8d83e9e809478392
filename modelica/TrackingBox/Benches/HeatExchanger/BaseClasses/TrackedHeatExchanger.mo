within TrackingBox.Benches.HeatExchanger.BaseClasses;
model TrackedHeatExchanger "Counter-flow heat exchanger with the bench's tracking bounds on kht (500..1500 W/(m2.K))"
  extends TrackingBox.Fluid.HeatExchanger(kht(min=500, max=1500));
  annotation (Documentation(info="<html>
<p><code>Fluid.HeatExchanger</code> unchanged (same equations, same default
values), with the range the bench allows the heat-transfer coefficient
<code>kht</code>: 500..1500 W/(m2.K), half to one and a half times the
twin's design value of 1000. The twin's tracking bounds and the values a
bench case may give the plant (<code>trackingbox bench heat-exchanger --set
hx.kht=...</code>) are both checked against this range.</p>
<p>Why a class of its own: the bounds are declared where <code>kht</code> gets
its type for this bench, so that both <code>Twin</code> (which keeps the
design value) and <code>Plant</code> (which sets <code>hx(kht=910)</code>
through its <code>extends</code> clause) carry them. Declared as
<code>hx(kht(min=500, max=1500)=1000)</code> on the component in
<code>PartialBench</code>, they were lost in <code>Plant</code>: rumoca 0.10.2
replaces, rather than merges, a declaration's modification of
<code>hx.kht</code> with the one given through <code>extends</code>.</p>
</html>"));
end TrackedHeatExchanger;
