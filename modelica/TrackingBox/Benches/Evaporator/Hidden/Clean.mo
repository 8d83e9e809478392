within TrackingBox.Benches.Evaporator.Hidden;
model Clean "Evaporator plant with only what the twin describes: fouling, boiling-point offset, wear"
  extends TrackingBox.Benches.Evaporator.Plant(ventFraction=0, UA_lossEffect=0, UA_lossFlash=0, DSbias=0,
    DSdrift=0, kScale=0);
  annotation (Documentation(info="<html>
<p>The no-effect case of the suite: the plant fouls (asymptotically, as
<code>Plant</code>), its liquor boils 1 K above the correlation in the effect,
its valves and pump are worn; the twin tracks the fouling and estimates the
rest. No vent, no heat loss, no soluble scale, no dry-solids meter error.</p>
</html>"));
end Clean;
