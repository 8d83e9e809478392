within TrackingBox.Evaporation.BaseClasses;
partial model PartialVessel "Well-mixed liquor volume boiling into a vapour space that vents through a vapour line"
  import TrackingBox.Media.BlackLiquor;
  import TrackingBox.Media.Water.Saturation;
  import TrackingBox.Evaporation.Functions;
  constant Real R_w(unit="J/(kg.K)") = 461.5 "Specific gas constant of water vapour";
  parameter TrackingBox.Units.Area A_sump = 2 "Cross-section of the liquid space above the level's zero";
  parameter TrackingBox.Units.Volume V_hold = 0 "Liquid held below the level's zero (film, sump cone, piping)";
  parameter TrackingBox.Units.Height H = 3 "Height of the liquid space above the level's zero (the level must stay in 0..H)";
  parameter TrackingBox.Units.Height z_out = 0 "Elevation of the level's zero above the outlet port (port_b)";
  parameter TrackingBox.Units.Volume V_vap = 5 "Volume of the vapour space";
  parameter TrackingBox.Units.Temperature T_ref_vap = 373.15 "Temperature in the ideal-gas law of the vapour space (fixed: it sets the vapour capacity only)";
  parameter TrackingBox.Units.MassFlowRate m_flow_vap_nominal = 1 "Vapour-line flow at dp_vap_nominal";
  parameter TrackingBox.Units.PressureDifference dp_vap_nominal = 5000 "Vapour-line pressure drop at m_flow_vap_nominal";
  parameter TrackingBox.Units.PressureDifference dp_vap_small = 100 "Regularisation of the vapour-line square-root law";
  parameter Real K_ev(unit="kg/(s.K)") = 5 "Evaporation per kelvin of liquid temperature above the boiling point";
  parameter TrackingBox.Units.TemperatureDifference dT_smooth = 0.01 "Smoothing width of the evaporation law";
  parameter TrackingBox.Units.TemperatureDifference dBPR = 0 "Offset added to the boiling point (plant: composition effects), used when use_dBPR_in = false";
  parameter Boolean use_dBPR_in = false "= true to take the boiling-point offset from the input dBPR_in";
  parameter Real epsBPR(unit="1") = 0 "Relative error of the boiling-point rise (plant)";
  parameter TrackingBox.Units.ThermalConductance UA_loss = 0 "Heat-loss conductance of the liquid to ambient";
  parameter TrackingBox.Units.Temperature T_amb = 293.15 "Ambient temperature";
  parameter TrackingBox.Units.Acceleration g = 9.81 "Gravity";
  parameter TrackingBox.Units.MassFlowRate m_flow_corr = 0 "Correction flow into the liquid (state compensation), added to m_flow_corr_in";
  parameter Boolean use_m_flow_corr_in = false "= true to add the input m_flow_corr_in to the correction flow";
  parameter Boolean use_heatLoss = false "= true to take an extra heat loss from the input Q_flow_loss_in (diagnosis hook)";
  parameter Boolean use_vapourCapacity_in = false "= true to scale the vapour line's flow by the input vapourCapacity_in (diagnosis hook)";
  parameter Boolean use_entrainment_in = false "= true to let the input m_flow_entrain_in of liquor leave with the vapour (diagnosis hook)";
  parameter TrackingBox.Units.Fraction x_start = 0.5 "Initial dry-solids fraction";
  parameter TrackingBox.Units.Temperature T_start = 373.15 "Initial liquid temperature";
  parameter TrackingBox.Units.Height L_start = 1 "Initial level";
  parameter TrackingBox.Units.Pressure p_start = 1e5 "Initial vapour-space pressure";
  parameter TrackingBox.Units.Mass M_start = BlackLiquor.density(x_start, T_start)*(V_hold + A_sump*L_start) "Initial liquid mass";
  parameter TrackingBox.Units.Mass M_vap_start = p_start*V_vap/(R_w*T_ref_vap) "Initial vapour mass";
  TrackingBox.Evaporation.LiquorPort_a port_a "Liquid inlet (enters the vapour space from above)"
    annotation (Placement(transformation(extent={{-110,50},{-90,70}})));
  TrackingBox.Evaporation.LiquorPort_b port_b "Liquid outlet at the bottom"
    annotation (Placement(transformation(extent={{-10,-110},{10,-90}})));
  TrackingBox.Interfaces.FluidPort_b port_v "Vapour outlet"
    annotation (Placement(transformation(extent={{-10,90},{10,110}})));
  TrackingBox.Interfaces.RealInput m_flow_corr_in(unit="kg/s") if use_m_flow_corr_in "Correction flow from outside"
    annotation (Placement(transformation(extent={{-140,-40},{-100,0}})));
  TrackingBox.Interfaces.RealInput dBPR_in(unit="K") if use_dBPR_in "Boiling-point offset from outside"
    annotation (Placement(transformation(extent={{-140,-90},{-100,-50}})));
  TrackingBox.Interfaces.RealInput Q_flow_loss_in(unit="W") if use_heatLoss "Extra heat lost by the liquid (diagnosis hook)"
    annotation (Placement(transformation(origin={60,-120}, extent={{-20,-20},{20,20}}, rotation=90)));
  TrackingBox.Interfaces.RealInput vapourCapacity_in(unit="1") if use_vapourCapacity_in "Vapour-line flow as a fraction of its design law (diagnosis hook)"
    annotation (Placement(transformation(origin={40,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput m_flow_entrain_in(unit="kg/s") if use_entrainment_in "Liquor leaving with the vapour as droplets (diagnosis hook)"
    annotation (Placement(transformation(origin={-40,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealOutput dp_level(unit="Pa") "Hydrostatic pressure of the liquid above the level's zero (what a dP transmitter sees)"
    annotation (Placement(transformation(extent={{100,-90},{120,-70}})));
  TrackingBox.Units.Mass M(start=M_start, fixed=true) "Liquid mass";
  TrackingBox.Units.Mass M_s(start=x_start*M_start, fixed=true) "Dry-solids mass";
  TrackingBox.Units.Temperature T(start=T_start, fixed=true) "Liquid temperature";
  TrackingBox.Units.Mass M_vap(start=M_vap_start, fixed=true) "Vapour mass in the vapour space";
  TrackingBox.Units.Fraction x "Dry-solids fraction";
  Real h(unit="J/kg") "Specific enthalpy of the liquid";
  Real h_in(unit="J/kg") "Specific enthalpy of the inflow";
  Real h_vap(unit="J/kg") "Specific enthalpy of the vapour leaving the liquid";
  Real dhdx(unit="J/kg") "Partial derivative of h in x";
  TrackingBox.Units.SpecificHeatCapacity cp "Specific heat capacity of the liquid";
  TrackingBox.Units.Density rho "Density of the liquid";
  TrackingBox.Units.Height level "Level above the level's zero";
  TrackingBox.Units.Pressure p_vap "Vapour-space pressure";
  TrackingBox.Units.Temperature T_vap "Saturation temperature of the vapour space";
  TrackingBox.Units.TemperatureDifference BPR "Boiling-point rise";
  TrackingBox.Units.Temperature T_b "Boiling temperature of the liquid";
  TrackingBox.Units.MassFlowRate m_in "Inflow";
  TrackingBox.Units.MassFlowRate m_out "Outflow at the bottom";
  TrackingBox.Units.MassFlowRate m_ev "Evaporation (or flash) rate";
  TrackingBox.Units.MassFlowRate m_vap_out "Vapour flow out through the vapour line";
  TrackingBox.Units.MassFlowRate m_corr "Correction flow (at the vessel's own x and T)";
  TrackingBox.Units.HeatFlowRate Q "Heat into the liquid (from a steam chest; 0 in tanks)";
  TrackingBox.Units.HeatFlowRate Q_loss "Heat loss to ambient";
  Real dMdt(unit="kg/s") "Rate of change of the liquid mass";
  Real dMsdt(unit="kg/s") "Rate of change of the dry-solids mass";
  Real dxdt(unit="1/s") "Rate of change of the dry-solids fraction";
protected
  TrackingBox.Interfaces.RealInput m_flow_corr_internal(unit="kg/s") "Correction flow from outside (0 without input)";
  TrackingBox.Interfaces.RealInput dBPR_internal(unit="K") "Used boiling-point offset";
  TrackingBox.Interfaces.RealInput Q_flow_loss_internal(unit="W") "Extra heat loss (0 without the hook)";
  TrackingBox.Interfaces.RealInput vapourCapacity_internal(unit="1") "Vapour-line capacity factor (1 without the hook)";
  TrackingBox.Interfaces.RealInput m_flow_entrain_internal(unit="kg/s") "Entrained liquor (0 without the hook)";
equation
  connect(m_flow_corr_in, m_flow_corr_internal);
  connect(dBPR_in, dBPR_internal);
  connect(Q_flow_loss_in, Q_flow_loss_internal);
  connect(vapourCapacity_in, vapourCapacity_internal);
  connect(m_flow_entrain_in, m_flow_entrain_internal);
  if not use_heatLoss then
    Q_flow_loss_internal = 0;
  end if;
  if not use_vapourCapacity_in then
    vapourCapacity_internal = 1;
  end if;
  if not use_entrainment_in then
    m_flow_entrain_internal = 0;
  end if;
  if not use_dBPR_in then
    dBPR_internal = dBPR;
  end if;
  if not use_m_flow_corr_in then
    m_flow_corr_internal = 0;
  end if;
  m_corr = m_flow_corr + m_flow_corr_internal;
  m_in = port_a.m_flow;
  m_out = -port_b.m_flow;
  x = M_s/M;
  h = BlackLiquor.specificEnthalpy(x, T);
  h_in = BlackLiquor.specificEnthalpy(port_a.x, port_a.T);
  dhdx = Functions.enthalpyDerivativeX(x, T);
  cp = BlackLiquor.cp(x, T);
  rho = BlackLiquor.density(x, T);
  level = (M/rho - V_hold)/A_sump;
  dp_level = rho*g*level;
  p_vap = M_vap*R_w*T_ref_vap/V_vap;
  T_vap = Saturation.TSat(p_vap);
  h_vap = Saturation.hVapour(T_vap);
  BPR = BlackLiquor.boilingPointRise(x, p_vap);
  T_b = T_vap + dBPR_internal + (1 + epsBPR)*BPR;
  m_ev = K_ev*Functions.splus(T - T_b, dT_smooth);
  m_vap_out = vapourCapacity_internal*m_flow_vap_nominal*Functions.regRoot(p_vap - port_v.p, dp_vap_small)/sqrt(dp_vap_nominal);
  der(M_vap) = m_ev - m_vap_out;
  port_v.m_flow = -m_vap_out;
  port_v.T = T_vap;
  port_a.p = p_vap;
  port_b.p = p_vap + rho*g*(level + z_out);
  port_b.x = x;
  port_b.T = T;
  Q_loss = UA_loss*(T - T_amb) + Q_flow_loss_internal;
  dMdt = m_in - m_out - m_ev + m_corr - m_flow_entrain_internal;
  dMsdt = port_a.x*m_in - x*m_out + x*m_corr - x*m_flow_entrain_internal;
  der(M) = dMdt;
  der(M_s) = dMsdt;
  dxdt = (dMsdt - x*dMdt)/M;
  M*cp*der(T) + M*dhdx*dxdt + h*dMdt = m_in*h_in - m_out*h - m_ev*h_vap + m_corr*h - m_flow_entrain_internal*h + Q - Q_loss;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Rectangle(extent={{-60,100},{60,-100}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid), Rectangle(extent={{-60,-10},{60,-100}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Solid), Text(extent={{-150,-112},{150,-142}}, textString="%name", textColor={0,0,255})}), Documentation(info="<html>
<p>States: liquid mass <code>M</code>, dry-solids mass <code>M_s</code>,
temperature <code>T</code> and vapour mass <code>M_vap</code>. The energy
balance is that of the inventory <code>M&middot;h(x, T)</code>:
<code>M&middot;cp&middot;dT/dt + M&middot;(&part;h/&part;x)&middot;dx/dt + h&middot;dM/dt</code>
equals the enthalpy flows, so it is exact, not only for slowly varying
<code>x</code>. The liquid boils as a smooth relaxation towards the boiling
point: <code>m_ev = K_ev&middot;s&#8314;(T - T_b)</code> with
<code>T_b = TSat(p_vap) + dBPR + (1 + epsBPR)&middot;BPR(x, p_vap)</code>;
the vapour leaves the liquid with <code>hVapour(TSat(p_vap))</code>.</p>
<p>The vapour space is an ideal gas at the fixed temperature
<code>T_ref_vap</code> (<code>p_vap = M_vap&middot;R_w&middot;T_ref_vap/V_vap</code>):
the vapour mass balance is exact; the fixed temperature only sets how fast the
pressure moves. The vapour line follows the regularised square-root law.
The correction flow <code>m_corr</code> enters at the vessel's own
<code>x</code> and <code>h</code>: it changes the mass, never the composition
or the temperature.</p>
<p>Diagnosis hooks (off by default; off, the equations are those without them:
the internal signals are 0, or 1 for the capacity factor): <code>use_heatLoss</code>
adds the input <code>Q_flow_loss_in</code> (W) to the heat loss;
<code>use_vapourCapacity_in</code> multiplies the vapour line's flow by
<code>vapourCapacity_in</code>; <code>use_entrainment_in</code> lets
<code>m_flow_entrain_in</code> (kg/s) of liquid leave with the vapour, at the
liquid's own dry solids and enthalpy (the vapour line's flow is the evaporation's
alone: the droplets do not change the vapour space's pressure).</p>
<p>Level: <code>(M/&rho; - V_hold)/A_sump</code>; <code>dp_level =
&rho;&middot;g&middot;level</code> is what a dP transmitter with its lower tap at the
level's zero sees.</p>
</html>"));
end PartialVessel;
