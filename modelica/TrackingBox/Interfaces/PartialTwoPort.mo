within TrackingBox.Interfaces;
partial model PartialTwoPort "Component with an inlet and an outlet, no storage of mass"
  FluidPort_a port_a "Inlet (design flow direction from port_a to port_b)"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  FluidPort_b port_b "Outlet"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
  TrackingBox.Units.MassFlowRate m_flow "Mass flow rate from port_a to port_b";
  TrackingBox.Units.PressureDifference dp "Pressure difference port_a.p - port_b.p";
equation
  port_a.m_flow + port_b.m_flow = 0;
  m_flow = port_a.m_flow;
  dp = port_a.p - port_b.p;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Line(points={{-100,0},{100,0}}, color={0,127,255}, thickness=0.5)}),
    Documentation(info="<html>
<p>Mass balance without storage; extending models add one pressure relation
and set <code>port_b.T</code>.</p>
</html>"));
end PartialTwoPort;
