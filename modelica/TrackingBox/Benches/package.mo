within TrackingBox;
package Benches "Test benches: a plant model and a digital twin each"
  annotation (Documentation(info="<html>
<p>Each bench has a <code>Plant</code> (stands in for the physical process:
degraded parameters, quadratic curves) and a <code>Twin</code> (the
simulator to be tracked), with identical top-level inputs and outputs, and a
<code>Validation</code> package with one wrapper per model that binds the
inputs to functions of time.</p>
</html>"));
end Benches;
