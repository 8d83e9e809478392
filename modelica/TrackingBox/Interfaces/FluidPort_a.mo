within TrackingBox.Interfaces;
connector FluidPort_a "Inlet port (design flow into the component); reads T from upstream"
  extends FluidPort;
  annotation (
    Documentation(info="<html>
<p>The inlet of a component (<code>port_a</code>), drawn as a filled circle:
the design flow enters here, <code>m_flow &gt; 0</code> (the flow variable is
positive into the component). The component <em>reads</em> the temperature
<code>T</code> of the entering water from the connection (the upstream
<code>port_b</code> sets it). Same variables as <code>FluidPort</code>.</p>
</html>"));
end FluidPort_a;
