within TrackingBox.Benches.Evaporator;
package BaseClasses "The slice shared by plant and twin"
  annotation (Documentation(info="<html>
<p><code>PartialSlice</code> is the last-effect slice that plant and twin
share: feed source and flow loop, the falling-film effect with its level loop,
the product flash tank, pump and product valve, the condensate tank and the
steam supply in ratio to the feed, with their instruments. The
<code>Tracked...</code> classes add the bench's bounds to the inlet and outlet
valves' capacity and to the product pump's curve.</p>
</html>"));
end BaseClasses;
