within TrackingBox.Benches;
package HeatProduction "Test bench 2: heat-production process (after Martinez et al. 2018)"
  annotation (Documentation(info="<html>
<p>Water circuit: preheating tank <code>T100</code> (electric preheater,
temperature controller <code>TIC100</code>) &rarr; pump <code>PU100</code>,
<code>Pipe100</code>, valve <code>V100</code> (level controller
<code>LIC200</code> on the pump speed) &rarr; storage tank <code>T200</code>
&rarr; pump <code>PU200</code>, <code>Pipe200</code>, <code>V200</code> &rarr;
pressurised heating unit <code>HU300</code> (heating-medium temperature set by
<code>TIC300</code>) &rarr; heat exchanger <code>HEX300</code> (hot side)
&rarr; <code>Pipe201</code>, <code>V300</code> &rarr; back to <code>T100</code>.
The external cold stream (heat demand: flow and inlet temperature) passes the
cold side of <code>HEX300</code>; its outlet temperature is controlled by
<code>TIC302</code> on the speed of <code>PU200</code>. The elevated make-up
tank <code>T400</code> (filled with make-up water by <code>LIC400</code>)
drains through <code>Pipe101</code> and <code>V400</code> into <code>T100</code>
(level controller <code>LIC100</code> on <code>V400</code>); a constant bleed
leaves at the bottom of <code>T100</code>, so excess water is discharged and
make-up flows continuously.</p>
<p><code>Plant</code>: quadratic pipe and pump curves, degraded components.
<code>Twin</code>: linear curves, the initial values of the method notes, and
correction-flow inputs for its tanks.</p>
</html>"));
end HeatProduction;
