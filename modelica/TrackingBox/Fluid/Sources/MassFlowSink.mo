within TrackingBox.Fluid.Sources;
model MassFlowSink "Sink with prescribed mass flow rate"
  parameter TrackingBox.Units.MassFlowRate m_flow = 0 "Mass flow rate drawn, used when use_m_flow_in = false";
  parameter Boolean use_m_flow_in = false "= true to take the flow from the input m_flow_in";
  TrackingBox.Interfaces.RealInput m_flow_in(unit="kg/s") if use_m_flow_in "Mass flow rate drawn";
  TrackingBox.Interfaces.FluidPort_a port "Inlet";
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
  annotation (Documentation(info="<html><p>Draws <code>m_flow</code> from the connection (e.g. a drain or bleed).</p></html>"));
end MassFlowSink;
