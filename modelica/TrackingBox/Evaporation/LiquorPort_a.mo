within TrackingBox.Evaporation;
connector LiquorPort_a "Liquor inlet port (design flow into the component); reads x and T from upstream"
  extends TrackingBox.Evaporation.LiquorPort;
  annotation (
    Documentation(info="<html>
<p>The liquid inlet of an evaporation component (<code>port_a</code>), drawn as
a filled brown circle: the design flow enters here (<code>m_flow &gt; 0</code>),
and the component reads the dry-solids fraction <code>x</code> and the
temperature <code>T</code> of the entering liquor (or condensate,
<code>x = 0</code>) from the upstream <code>port_b</code>.</p>
</html>"));
end LiquorPort_a;
