within TrackingBox.Benches;
package Evaporator "Last effect of a black-liquor evaporation plant (1/10 scale): plant and twin"
  annotation (Documentation(info="<html>
<p>The slice of the source thesis: liquor from a pressure source through a
flow-controlled inlet valve into a falling-film effect whose level a PI holds
with the outlet valve; a flash tank whose level a PI holds with the product
valve after the pump; the condensate from the steam chest into a condensate
tank with its own level loop; steam from a pressure source at
<code>steamP</code> through a steam valve in ratio to the measured feed flow;
the effect's vapour and the condensate flash to the next effect's pressure
<code>nextP</code>, the flash vapour to a header at <code>flashSinkP</code>.</p>
<p><code>Plant</code> and <code>Twin</code> have the same inputs and outputs
(the twin adds the three correction-flow inputs).</p>
</html>"));
end Evaporator;
