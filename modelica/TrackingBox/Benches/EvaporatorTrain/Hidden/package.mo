within TrackingBox.Benches.EvaporatorTrain;
package Hidden "Train plant variants with effects the twin lacks (the hidden-effect suite of diagnose on the train)"
  annotation (Documentation(info="<html>
<p><code>Clean</code> is the train's <code>Plant</code> with only what the suite
twin describes: every effect fouls (asymptotically, as <code>Plant</code>), the
liquor boils above the correlation by each effect's offset, the feed valve and
the transfer pumps are worn; no steam-chest vent, no shell or flash-tank heat
loss, no soluble scale, a true product dry-solids meter. Every other model is
<code>Clean</code> plus an effect on one named effect of the train (or two),
written independently of the diagnosis templates: the vent is an orifice whose
flow grows with the square root of the chest's overpressure (the template vents
a fixed fraction of the condensate), the shell loss is natural convection growing
with the 1.25 power of the temperature difference to the hall (the template is
linear in it). The magnitudes follow the train's design (a share of effect 1's
design steam, a share of the effect's design duty), so they hold for any
<code>N</code>. <code>trackingbox bench evaporator-train --hidden CASE</code>
writes a case.</p>
</html>"));
end Hidden;
