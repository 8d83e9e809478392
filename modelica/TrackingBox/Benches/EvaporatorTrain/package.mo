within TrackingBox.Benches;
package EvaporatorTrain "Multi-effect black-liquor evaporator train (N effects, backward feed, 1/10 scale): plant and twin"
  annotation (Documentation(info="<html>
<p>A whole train of <code>N</code> falling-film effects (default 7) built from
the <code>TrackingBox.Evaporation</code> components: live steam into effect 1,
the vapour of effect <code>k</code> heating effect <code>k+1</code> through a
vapour header, the last vapour to a surface condenser (a pressure boundary),
backward liquor feed with transfer pumps and level valves, a product flash
tank, the condensate cascade through one flash tank per effect. See
<code>BaseClasses.PartialTrain</code> for the design point.</p>
<p><code>Plant</code> and <code>Twin</code> have the same inputs and outputs
(the twin adds the correction-flow inputs of every vessel).</p>
</html>"));
end EvaporatorTrain;
