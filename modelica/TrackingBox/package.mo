within;
package TrackingBox "Thermal-fluid models and test benches for tracking simulators"
  annotation (Documentation(info="<html>
<p>Self-contained library (no Modelica Standard Library needed) for the
trackingbox toolchain: SI types (<code>Units</code>), connectors
(<code>Interfaces</code>), water properties (<code>Media.Water</code>),
a PI controller with hold and manual mode (<code>Blocks</code>),
thermal-fluid components (<code>Fluid</code>) and two test benches with a
plant model and a digital twin each (<code>Benches</code>).</p>
<p>Conventions: flow is directed from <code>port_a</code> to <code>port_b</code>;
see <code>Interfaces.FluidPort</code>. Trackable parameters offer the
conditional-input pattern <code>use_X_in</code> / <code>X_in</code>.</p>
</html>"));
end TrackingBox;
