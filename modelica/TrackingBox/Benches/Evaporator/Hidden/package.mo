within TrackingBox.Benches.Evaporator;
package Hidden "Plant variants with effects the twin lacks (the hidden-effect suite of diagnose)"
  annotation (Documentation(info="<html>
<p><code>Clean</code> is the bench's <code>Plant</code> with only what the twin
describes: the fouling (which the twin tracks), the boiling-point offset of the
effect, the worn valves and pump (which it estimates); no vent, no heat loss, no
scale, a true dry-solids meter. Every other model is <code>Clean</code> plus one
effect (or two), written independently of the diagnosis templates: other
functional forms (a vent through an orifice where the template vents a fraction
of the condensate, a natural-convection loss growing with the 1.25 power of the
temperature difference where the template is linear, a demister whose resistance
grows with its load where the template restricts the line by a constant fraction,
a borate offset switching on above 72 % dry solids where the template scales the
boiling-point rise, scale growing with the supersaturation where the template
has a sigmoid onset, a density-based meter with the wrong liquor constant where
the template adds an offset and a drift) and other magnitudes. The effects act
from the start of the plant's run. <code>trackingbox bench evaporator --hidden
CASE</code> writes a case.</p>
</html>"));
end Hidden;
