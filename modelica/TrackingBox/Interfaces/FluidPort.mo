within TrackingBox.Interfaces;
connector FluidPort "Water port for directed flow"
  TrackingBox.Units.Pressure p "Pressure at the port (piezometric: includes the static head of the port's elevation)";
  flow TrackingBox.Units.MassFlowRate m_flow "Mass flow rate from the connection into the component";
  TrackingBox.Units.Temperature T "Temperature of the water flowing in the design direction";
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Ellipse(extent={{-100,100},{100,-100}}, lineColor={0,127,255}, fillColor={0,127,255}, fillPattern=FillPattern.Solid)}),
    Documentation(info="<html>
<p>Flow is <em>directed</em>: every two-port component is designed for flow from
<code>port_a</code> (inlet) to <code>port_b</code> (outlet). The temperature
<code>T</code> is a potential set by exactly one side of a connection: the
upstream component's outlet (<code>port_b.T = its outlet temperature</code>);
the downstream component reads it at its <code>port_a</code>. Reverse flow is
tolerated numerically but carries the design-direction temperature.</p>
<p>Rules that follow: a <code>port_b</code> may be connected to several
<code>port_a</code> (a split: all branches get the same temperature); streams
are merged only in components with a mixing volume (tanks, which have an
array of inlets). Pressures are piezometric (absolute pressure plus
&rho;&middot;g&middot;z), so pipes carry no elevation term; tanks add their
elevation to the port pressures.</p>
</html>"));
end FluidPort;
