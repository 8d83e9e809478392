within TrackingBox.Interfaces;
partial model PartialTwoPort "Component with an inlet and an outlet, no storage of mass"
  FluidPort_a port_a "Inlet (design flow direction from port_a to port_b)";
  FluidPort_b port_b "Outlet";
  TrackingBox.Units.MassFlowRate m_flow "Mass flow rate from port_a to port_b";
  TrackingBox.Units.PressureDifference dp "Pressure difference port_a.p - port_b.p";
equation
  port_a.m_flow + port_b.m_flow = 0;
  m_flow = port_a.m_flow;
  dp = port_a.p - port_b.p;
  annotation (Documentation(info="<html>
<p>Mass balance without storage; extending models add one pressure relation
and set <code>port_b.T</code>.</p>
</html>"));
end PartialTwoPort;
