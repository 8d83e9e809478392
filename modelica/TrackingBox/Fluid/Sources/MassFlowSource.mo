within TrackingBox.Fluid.Sources;
model MassFlowSource "Source with prescribed mass flow rate and temperature"
  parameter TrackingBox.Units.MassFlowRate m_flow = 1 "Mass flow rate delivered, used when use_m_flow_in = false";
  parameter TrackingBox.Units.Temperature T = 293.15 "Temperature, used when use_T_in = false";
  parameter Boolean use_m_flow_in = false "= true to take the flow from the input m_flow_in";
  parameter Boolean use_T_in = false "= true to take the temperature from the input T_in";
  TrackingBox.Interfaces.RealInput m_flow_in(unit="kg/s") if use_m_flow_in "Mass flow rate delivered";
  TrackingBox.Interfaces.RealInput T_in(unit="K") if use_T_in "Temperature";
  TrackingBox.Interfaces.FluidPort_b port "Outlet";
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
  annotation (Documentation(info="<html><p>Delivers <code>m_flow</code> at temperature <code>T</code>.</p></html>"));
end MassFlowSource;
