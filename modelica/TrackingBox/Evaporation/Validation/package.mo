within TrackingBox.Evaporation;
package Validation "Validation models for the evaporation components"
  annotation (Documentation(info="<html>
<p><code>SliceBalance</code>: the evaporator slice of
<code>Benches.Evaporator.Twin</code> under varying boundaries and correction
flows, with integrators of everything that crosses its boundary, so that a
test can check the mass, dry-solids and energy balances of the assembled
components to the solver's tolerance.</p>
</html>"));
end Validation;
