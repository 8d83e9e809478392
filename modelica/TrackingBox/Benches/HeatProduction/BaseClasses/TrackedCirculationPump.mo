within TrackingBox.Benches.HeatProduction.BaseClasses;
model TrackedCirculationPump "Pump PU200 (T200 through HU300 and HEX300) with the bench's tracking bounds on VFlowDesign and uRise"
  extends TrackingBox.Fluid.Pump(VFlowDesign(min=7.5e-5, max=9.16e-5), uRise(min=36000, max=44000));
  annotation (Documentation(info="<html>
<p><code>Fluid.Pump</code> unchanged, with the ranges the bench allows the
design point of <code>PU200</code>: <code>VFlowDesign</code>
7.5e-5..9.16e-5 m3/s (design 8.3e-5, about &plusmn; 10 %) and
<code>uRise</code> 36..44 kPa (design 40 kPa, &plusmn; 10 %). Declared in a
class so that <code>Plant</code>, which sets
<code>PU200(VFlowDesign=8.1e-5, uRise=38500)</code> through its
<code>extends</code> clause, keeps the bounds (see
<code>TrackedHeatingUnit</code>).</p>
</html>"));
end TrackedCirculationPump;
