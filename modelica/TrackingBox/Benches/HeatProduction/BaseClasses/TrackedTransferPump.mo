within TrackingBox.Benches.HeatProduction.BaseClasses;
model TrackedTransferPump "Pump PU100 (T100 to T200) with the bench's tracking bounds on VFlowDesign and uRise"
  extends TrackingBox.Fluid.Pump(VFlowDesign(min=6.0e-5, max=7.3e-5), uRise(min=36000, max=44000));
  annotation (Documentation(info="<html>
<p><code>Fluid.Pump</code> unchanged, with the ranges the bench allows the
design point of <code>PU100</code>: <code>VFlowDesign</code>
6.0e-5..7.3e-5 m3/s (design 6.6e-5, about &plusmn; 10 %) and
<code>uRise</code> 36..44 kPa (design 40 kPa, &plusmn; 10 %). Declared in a
class so that <code>Plant</code>, which sets
<code>PU100(VFlowDesign=6.3e-5, uRise=37500)</code> through its
<code>extends</code> clause, keeps the bounds (see
<code>TrackedHeatingUnit</code>).</p>
</html>"));
end TrackedTransferPump;
