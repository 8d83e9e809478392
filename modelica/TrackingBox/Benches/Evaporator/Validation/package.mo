within TrackingBox.Benches.Evaporator;
package Validation "Plant and twin driven by time functions: a flow stoppage"
  annotation (Documentation(info="<html>
<p><code>PlantStoppage</code> and <code>TwinStoppage</code>: the slice at its
design point through a one-hour feed stoppage (the feed setpoint goes to
0.5 % of design within a minute and back an hour later). The steam follows
the feed, so the effect neither boils dry nor floods; the levels must stay in
their vessels and the temperatures must not jump.</p>
</html>"));
end Validation;
