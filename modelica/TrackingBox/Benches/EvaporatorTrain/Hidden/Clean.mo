within TrackingBox.Benches.EvaporatorTrain.Hidden;
model Clean "Train plant with only what the twin describes: fouling, boiling-point offsets, wear"
  extends TrackingBox.Benches.EvaporatorTrain.Plant(ventFractionAll=0, UA_lossAll=0, UA_lossFlash=0, DSbias=0,
    DSdrift=0, kScale=0);
  annotation (Documentation(info="<html>
<p>The no-effect case of the train's suite: every effect fouls (as
<code>Plant</code>), boils above the correlation by its offset, the feed valve
and the transfer pumps are worn; the twin tracks the fouling and estimates the
rest. No vent, no heat loss, no soluble scale, no dry-solids meter error.</p>
</html>"));
end Clean;
