within TrackingBox;
package Blocks "Control blocks"
  annotation (Documentation(info="<html>
<p>Controller blocks. <code>PI</code> is the plant-side controller of the
process models (limits, anti-windup, hold, manual mode).
<code>ParameterController</code> and <code>StateCompensation</code> are the
tracking law: a generated tracking box instantiates one
<code>ParameterController</code> per tracked parameter and one
<code>StateCompensation</code> per compensated level, and the Python runtime
(<code>trackingbox.tracking.controllers</code>) implements exactly the same
laws (tested step for step against the compiled blocks).</p>
<p>Boolean signals are not used: logical inputs are Real signals, true when
greater than 0.5.</p>
</html>"));
end Blocks;
