within TrackingBox.Fluid.Sources;
model MassFlowSink "Sink with prescribed mass flow rate"
  parameter TrackingBox.Units.MassFlowRate m_flow = 0 "Mass flow rate drawn, used when use_m_flow_in = false";
  parameter Boolean use_m_flow_in = false "= true to take the flow from the input m_flow_in";
  TrackingBox.Interfaces.RealInput m_flow_in(unit="kg/s") if use_m_flow_in "Mass flow rate drawn"
    annotation (Placement(transformation(origin={120,0}, extent={{-20,-20},{20,20}}, rotation=180)));
  TrackingBox.Interfaces.FluidPort_a port "Inlet"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  TrackingBox.Units.Temperature T "Temperature of the water drawn";
protected
  TrackingBox.Interfaces.RealInput m_flow_internal(unit="kg/s") "Used flow";
equation
  connect(m_flow_in, m_flow_internal);
  if not use_m_flow_in then
    m_flow_internal = m_flow;
  end if;
  port.m_flow = m_flow_internal;
  T = port.T;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-100,60},{100,-60}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.HorizontalCylinder),
      Polygon(points={{-80,30},{-20,0},{-80,-30},{-80,30}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Text(extent={{-10,30},{90,-30}}, textString="m", textColor={0,0,0}),
      Text(extent={{-150,110},{150,70}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Draws the mass flow rate <code>m_flow</code> (kg/s) from the connection, e.g. a
drain or a bleed: <code>port.m_flow = m_flow</code>. It sets no pressure and
reads the temperature <code>T</code> of the water it receives from upstream
(its port is a <code>FluidPort_a</code>). With <code>use_m_flow_in</code> the
flow comes from the input <code>m_flow_in</code>.</p>
</html>"));
end MassFlowSink;
