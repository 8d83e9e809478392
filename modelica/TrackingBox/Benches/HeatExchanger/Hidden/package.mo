within TrackingBox.Benches.HeatExchanger;
package Hidden "Plant variants with an effect the twin lacks (the hidden-effect suite of diagnose)"
  annotation (Documentation(info="<html>
<p>Each model is the bench's <code>Plant</code> plus one effect the twin does
not have, written independently of the diagnosis templates (other functional
forms: exponential fouling where the template is linear, a sensor drift that
levels off where the template grows linearly, a second-order sensor lag where
the template is first-order, a heat loss growing with the 1.25 power of the
temperature difference where the template is linear). <code>Bypass</code> is
outside the effect library. The effects start at <code>tStart</code> = 3600 s,
the end of the bench's warm-up, so they begin with the measured data.
<code>trackingbox bench heat-exchanger --hidden CASE</code> writes a case.</p>
</html>"));
end Hidden;
