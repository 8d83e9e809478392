within TrackingBox.Fluid;
model OpenTank "Open, well-mixed tank with level, mass and energy balance"
  parameter Integer nPorts_a = 1 "Number of inlets (entering above the water surface)";
  parameter TrackingBox.Units.Area A = 0.2 "Cross-section area";
  parameter TrackingBox.Units.Height zBottom = 0 "Elevation of the tank bottom (outlet port_b)";
  parameter TrackingBox.Units.Height zInlet = 1.5 "Elevation of the inlets (free inflow above the surface)";
  parameter TrackingBox.Units.Pressure pAmb = 101325 "Ambient pressure";
  parameter TrackingBox.Units.Acceleration g = 9.81 "Gravity";
  parameter TrackingBox.Units.ThermalConductance UA = 5 "Heat-loss conductance to ambient";
  parameter TrackingBox.Units.Temperature TAmb = 293.15 "Ambient temperature, used when use_TAmb_in = false";
  parameter TrackingBox.Units.Height level_start = 0.8 "Initial level";
  parameter TrackingBox.Units.Temperature T_start = 323.15 "Initial temperature";
  parameter TrackingBox.Units.MassFlowRate m_flow_corr = 0 "Correction flow into the tank (state compensation), added to m_flow_corr_in";
  parameter Boolean use_m_flow_corr_in = false "= true to add the input m_flow_corr_in to the correction flow";
  parameter Boolean use_Q_flow_in = false "= true for a heater with power from the input Q_flow_in";
  parameter Boolean use_TAmb_in = false "= true to take the ambient temperature from the input TAmb_in";
  parameter Boolean use_leak = false "= true for a leak: the flow m_flow_leak_in leaves the tank at the tank temperature";
  parameter Boolean use_heatLoss = false "= true for an extra heat loss Q_flow_loss_in to the surroundings";
  TrackingBox.Interfaces.FluidPort_a port_a[nPorts_a] "Inlets"
    annotation (Placement(transformation(extent={{-40,90},{40,110}})));
  TrackingBox.Interfaces.FluidPort_b port_b "Outlet at the bottom"
    annotation (Placement(transformation(extent={{-10,-110},{10,-90}})));
  TrackingBox.Interfaces.RealInput m_flow_corr_in(unit="kg/s") if use_m_flow_corr_in "Correction flow from outside"
    annotation (Placement(transformation(extent={{-140,40},{-100,80}})));
  TrackingBox.Interfaces.RealInput Q_flow_in(unit="W") if use_Q_flow_in "Heater power"
    annotation (Placement(transformation(extent={{-140,-20},{-100,20}})));
  TrackingBox.Interfaces.RealInput TAmb_in(unit="K") if use_TAmb_in "Ambient temperature"
    annotation (Placement(transformation(extent={{-140,-80},{-100,-40}})));
  TrackingBox.Interfaces.RealInput m_flow_leak_in(unit="kg/s") if use_leak "Leak flow leaving the tank"
    annotation (Placement(transformation(origin={120,-60}, extent={{-20,-20},{20,20}}, rotation=180)));
  TrackingBox.Interfaces.RealInput Q_flow_loss_in(unit="W") if use_heatLoss "Extra heat flow lost to the surroundings"
    annotation (Placement(transformation(origin={120,0}, extent={{-20,-20},{20,20}}, rotation=180)));
  TrackingBox.Units.Height level(start=level_start, fixed=true) "Water level";
  TrackingBox.Units.Temperature T(start=T_start, fixed=true) "Water temperature";
  TrackingBox.Units.Mass m "Water mass";
  TrackingBox.Units.Density rho "Density";
  TrackingBox.Units.SpecificHeatCapacity cp "Specific heat capacity";
  TrackingBox.Units.MassFlowRate m_flow_in "Sum of inlet flows";
  TrackingBox.Units.MassFlowRate m_flow_out "Outlet flow (positive out of the tank)";
  TrackingBox.Units.MassFlowRate m_flow_corr_total "Correction flow";
  TrackingBox.Units.HeatFlowRate H_flow_in "Enthalpy flow of the inlets relative to the tank temperature";
  TrackingBox.Units.HeatFlowRate Q_loss "Heat loss to ambient";
protected
  TrackingBox.Interfaces.RealInput m_flow_corr_internal(unit="kg/s") "Correction flow from outside (0 without input)";
  TrackingBox.Interfaces.RealInput Q_flow_internal(unit="W") "Used heater power";
  TrackingBox.Interfaces.RealInput TAmb_internal(unit="K") "Used ambient temperature";
  TrackingBox.Interfaces.RealInput m_flow_leak_internal(unit="kg/s") "Leak flow (0 without leak)";
  TrackingBox.Interfaces.RealInput Q_flow_loss_internal(unit="W") "Extra heat loss (0 without it)";
  TrackingBox.Units.MassFlowRate m_in[nPorts_a] "Inlet flows";
  TrackingBox.Units.HeatFlowRate H_in[nPorts_a] "Enthalpy flows of the inlets relative to the tank temperature";
equation
  connect(m_flow_corr_in, m_flow_corr_internal);
  connect(Q_flow_in, Q_flow_internal);
  connect(TAmb_in, TAmb_internal);
  connect(m_flow_leak_in, m_flow_leak_internal);
  connect(Q_flow_loss_in, Q_flow_loss_internal);
  if not use_m_flow_corr_in then
    m_flow_corr_internal = 0;
  end if;
  if not use_Q_flow_in then
    Q_flow_internal = 0;
  end if;
  if not use_TAmb_in then
    TAmb_internal = TAmb;
  end if;
  if not use_leak then
    m_flow_leak_internal = 0;
  end if;
  if not use_heatLoss then
    Q_flow_loss_internal = 0;
  end if;
  rho = TrackingBox.Media.Water.rho(T);
  cp = TrackingBox.Media.Water.cp(T);
  m = rho*A*level;
  for i in 1:nPorts_a loop
    m_in[i] = port_a[i].m_flow;
    H_in[i] = noEvent(max(port_a[i].m_flow, 0))*cp*(port_a[i].T - T);
    port_a[i].p = pAmb + rho*g*zInlet;
  end for;
  m_flow_in = sum(m_in);
  H_flow_in = sum(H_in);
  m_flow_out = -port_b.m_flow;
  m_flow_corr_total = m_flow_corr + m_flow_corr_internal;
  rho*A*der(level) = m_flow_in - m_flow_out + m_flow_corr_total - m_flow_leak_internal;
  Q_loss = UA*(T - TAmb_internal);
  m*cp*der(T) = H_flow_in + Q_flow_internal - Q_loss - Q_flow_loss_internal;
  port_b.p = pAmb + rho*g*(zBottom + level);
  port_b.T = T;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-80,80},{80,-100}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Rectangle(extent={{-80,0},{80,-100}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.Solid),
      Line(points={{-80,80},{-80,-100},{80,-100},{80,80}}, color={0,0,0}, thickness=0.5),
      Text(extent={{-75,60},{75,20}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Mass balance in the level (density at the tank temperature), energy balance
in the temperature: inlets bring their temperature (only when flowing in),
outflow and correction flow leave or enter at the tank temperature, plus
heater power and heat loss <code>UA&middot;(T - TAmb)</code>. Outlet pressure
<code>pAmb + &rho;&middot;g&middot;(zBottom + level)</code>; inlet pressure
<code>pAmb + &rho;&middot;g&middot;zInlet</code> (piezometric, free inflow).</p>
<p>State compensation: the correction flow <code>m_flow_corr</code> (tunable
parameter) plus the optional input <code>m_flow_corr_in</code> is added to the
mass balance. The level is not limited: keep it positive with the controls.</p>
<p>Hooks for diagnosis (off by default; off, the equations are those above):
<code>use_leak</code> takes a leak flow from the input <code>m_flow_leak_in</code>
(kg/s leaving the tank at the tank temperature, so it lowers the mass but
leaves the temperature balance unchanged); <code>use_heatLoss</code> takes an
extra heat loss from the input <code>Q_flow_loss_in</code> (W), subtracted in
the energy balance beside <code>UA&middot;(T - TAmb)</code>.</p>
</html>"));
end OpenTank;
