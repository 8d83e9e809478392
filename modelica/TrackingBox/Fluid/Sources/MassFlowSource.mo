within TrackingBox.Fluid.Sources;
model MassFlowSource "Source with prescribed mass flow rate and temperature"
  parameter TrackingBox.Units.MassFlowRate m_flow = 1 "Mass flow rate delivered, used when use_m_flow_in = false";
  parameter TrackingBox.Units.Temperature T = 293.15 "Temperature, used when use_T_in = false";
  parameter Boolean use_m_flow_in = false "= true to take the flow from the input m_flow_in";
  parameter Boolean use_T_in = false "= true to take the temperature from the input T_in";
  TrackingBox.Interfaces.RealInput m_flow_in(unit="kg/s") if use_m_flow_in "Mass flow rate delivered"
    annotation (Placement(transformation(extent={{-140,20},{-100,60}})));
  TrackingBox.Interfaces.RealInput T_in(unit="K") if use_T_in "Temperature"
    annotation (Placement(transformation(extent={{-140,-60},{-100,-20}})));
  TrackingBox.Interfaces.FluidPort_b port "Outlet"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
protected
  TrackingBox.Interfaces.RealInput m_flow_internal(unit="kg/s") "Used flow";
  TrackingBox.Interfaces.RealInput T_internal(unit="K") "Used temperature";
equation
  connect(m_flow_in, m_flow_internal);
  connect(T_in, T_internal);
  if not use_m_flow_in then
    m_flow_internal = m_flow;
  end if;
  if not use_T_in then
    T_internal = T;
  end if;
  port.m_flow = -m_flow_internal;
  port.T = T_internal;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-100,60},{100,-60}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.HorizontalCylinder),
      Polygon(points={{20,30},{80,0},{20,-30},{20,30}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Text(extent={{-90,30},{10,-30}}, textString="m", textColor={0,0,0}),
      Text(extent={{-150,110},{150,70}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Delivers the mass flow rate <code>m_flow</code> (kg/s) into the connection
at the temperature <code>T</code> (K): <code>port.m_flow = -m_flow</code>,
<code>port.T = T</code>. The pressure at the port is whatever the connected
network needs to take that flow (the source sets no pressure), so a network
fed by mass-flow sources needs a pressure boundary or a tank somewhere.
With <code>use_m_flow_in</code> and <code>use_T_in</code> the values come
from the inputs <code>m_flow_in</code> and <code>T_in</code> (the benches'
measured boundary flows and temperatures).</p>
</html>"));
end MassFlowSource;
