within TrackingBox.Blocks;
package Validation "Validation models for the blocks"
  annotation (Documentation(info="<html>
<p>Runnable models that check the blocks against what their documentation
states:</p>
<ul>
<li><code>PIHoldAndLimits</code>: <code>PI</code> on a first-order process
(<code>60 s&middot;dx/dt = y - x</code>) through a setpoint step, output
saturation and a hold; <code>tests/test_validation_models.py</code> compares it
with an independent integration of the law.</li>
<li><code>ParameterControllerInputs</code>: a direct and a reverse
<code>ParameterController</code> and a <code>StateCompensation</code> driven by
top-level inputs, so a test can feed them a recorded error sequence and
compare them step by step with the Python controllers.</li>
<li><code>ParameterControllerLoop</code>: a parameter controller tracking the
gain of a first-order twin through convergence, saturation at a bound, a hold
and its release.</li>
</ul>
</html>"));
end Validation;
