within TrackingBox.Benches.HeatProduction;
package Hidden "Plant variants with an effect the twin lacks (the hidden-effect suite of diagnose)"
  annotation (Documentation(info="<html>
<p>Each model is the bench's <code>Plant</code> plus one effect the twin does
not have, written independently of the diagnosis templates: a leak that grows
with the square root of the level (the template is constant), exponential
fouling (the template is linear), a heat loss growing with the 1.25 power of
the difference to the measured ambient temperature (the template is linear,
to a fixed 20 degC), a thermometer drift that levels off (the template grows
linearly). Effects that start do so at <code>tStart</code> = 14400 s, the end
of the bench's warm-up. <code>trackingbox bench heat-production --hidden
CASE</code> writes a case.</p>
</html>"));
end Hidden;
