within TrackingBox.Evaporation;
model Effect "Falling-film evaporator effect: liquor body with recirculation, vapour space, steam chest with condensate"
  extends TrackingBox.Evaporation.BaseClasses.PartialVessel(
    A_sump=3, V_hold=0.5, H=3, z_out=5, V_vap=10, T_ref_vap=383.15,
    m_flow_vap_nominal=0.7, dp_vap_nominal=5000, K_ev=5,
    x_start=0.77, T_start=404, L_start=1.2, p_start=1.46e5);
  import TrackingBox.Media.BlackLiquor;
  import TrackingBox.Media.Water.Saturation;
  import TrackingBox.Evaporation.Functions;
  parameter TrackingBox.Units.Area A = 300 "Heat-transfer area";
  parameter TrackingBox.Units.CoefficientOfHeatTransfer U0(min=100, max=3000) = 700 "Clean overall heat-transfer coefficient at the reference viscosity nu_ref";
  parameter Real Rf(unit="m2.K/W", min=0, max=6e-4) = 0 "Fouling resistance, used when use_Rf_in = false";
  parameter Boolean use_Rf_in = false "= true to take the fouling resistance from the input Rf_in";
  parameter Boolean use_U0_in = false "= true to take the clean coefficient from the input U0_in";
  parameter Boolean use_vent_in = false "= true to let the input m_flow_vent_in of steam leave the chest uncondensed (diagnosis hook)";
  parameter Boolean use_dRf_in = false "= true to add the input dRf_in to the fouling resistance (diagnosis hook)";
  parameter Real nu_ref(unit="m2/s") = 8e-5 "Reference kinematic viscosity (the liquor at about 79 % DS and 132 degC)";
  parameter Real n_visc(unit="1") = 0.41 "Exponent of the viscosity ratio in the clean coefficient";
  parameter TrackingBox.Units.MassFlowRate m_flow_rec = 10 "Recirculation flow (mixes with the feed on top of the tubes)";
  parameter TrackingBox.Units.Volume V_steam = 2 "Steam-chest volume";
  parameter TrackingBox.Units.Temperature T_ref_steam = 413.15 "Temperature in the ideal-gas law of the steam chest (sets its capacity only)";
  parameter TrackingBox.Units.MassFlowRate m_flow_steam_nominal = 1.4 "Steam flow through the fully open steam valve at dp_steam_nominal";
  parameter TrackingBox.Units.PressureDifference dp_steam_nominal = 5e4 "Steam-valve pressure drop at m_flow_steam_nominal";
  parameter TrackingBox.Units.PressureDifference dp_steam_small = 1000 "Regularisation of the steam-valve law";
  parameter TrackingBox.Units.Fraction steamLeakage = 1e-3 "Flow of the closed steam valve as a fraction of the open one";
  parameter TrackingBox.Units.Fraction ventFraction = 0 "Steam vented or leaking from the chest as a fraction of the condensate (plant)";
  parameter TrackingBox.Units.Pressure p_steam_start = 3.5e5 "Initial steam-chest pressure";
  TrackingBox.Interfaces.FluidPort_a port_s "Steam inlet (upstream of the effect's own steam valve)"
    annotation (Placement(transformation(extent={{90,50},{110,70}})));
  TrackingBox.Evaporation.LiquorPort_b port_c "Condensate outlet (drains freely at the condensing rate)"
    annotation (Placement(transformation(extent={{90,-30},{110,-10}})));
  TrackingBox.Interfaces.RealInput steamOpening(unit="1") "Steam-valve opening, 0..1"
    annotation (Placement(transformation(origin={60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput Rf_in(unit="m2.K/W") if use_Rf_in "Fouling resistance from outside"
    annotation (Placement(transformation(extent={{-140,0},{-100,40}})));
  TrackingBox.Interfaces.RealInput U0_in(unit="W/(m2.K)") if use_U0_in "Clean coefficient from outside"
    annotation (Placement(transformation(origin={-60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput m_flow_vent_in(unit="kg/s") if use_vent_in "Steam leaving the chest uncondensed (diagnosis hook)"
    annotation (Placement(transformation(origin={100,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput dRf_in(unit="m2.K/W") if use_dRf_in "Resistance of deposits beside Rf (diagnosis hook)"
    annotation (Placement(transformation(extent={{-140,30},{-100,70}})));
  TrackingBox.Units.Mass M_steam(start=p_steam_start*V_steam/(R_w*T_ref_steam), fixed=true) "Steam mass in the chest";
  TrackingBox.Units.Pressure p_s "Steam-chest pressure";
  TrackingBox.Units.Temperature T_s "Condensing temperature";
  TrackingBox.Units.Fraction x_d "Dry-solids fraction of the liquor distributed over the tubes (feed plus recirculation)";
  Real nu(unit="m2/s") "Kinematic viscosity of the distributed liquor";
  TrackingBox.Units.CoefficientOfHeatTransfer U_clean "Clean coefficient";
  TrackingBox.Units.CoefficientOfHeatTransfer U_eff "Effective coefficient with fouling";
  TrackingBox.Units.MassFlowRate m_steam "Steam flow into the chest";
  TrackingBox.Units.MassFlowRate m_c "Condensate flow";
  TrackingBox.Units.MassFlowRate m_vent "Vent flow from the chest";
  Real h_c(unit="J/kg") "Specific enthalpy of the condensate (saturated liquid at T_s)";
protected
  TrackingBox.Interfaces.RealInput Rf_internal(unit="m2.K/W") "Used fouling resistance";
  TrackingBox.Interfaces.RealInput U0_internal(unit="W/(m2.K)") "Used clean coefficient";
  TrackingBox.Interfaces.RealInput m_flow_vent_internal(unit="kg/s") "Extra vent (0 without the hook)";
  TrackingBox.Interfaces.RealInput dRf_internal(unit="m2.K/W") "Extra resistance (0 without the hook)";
  TrackingBox.Units.MassFlowRate m_feed_pos "Feed flow, smoothly kept positive for the mixing rule";
equation
  connect(Rf_in, Rf_internal);
  connect(U0_in, U0_internal);
  connect(m_flow_vent_in, m_flow_vent_internal);
  connect(dRf_in, dRf_internal);
  if not use_vent_in then
    m_flow_vent_internal = 0;
  end if;
  if not use_dRf_in then
    dRf_internal = 0;
  end if;
  if not use_Rf_in then
    Rf_internal = Rf;
  end if;
  if not use_U0_in then
    U0_internal = U0;
  end if;
  m_feed_pos = Functions.splus(m_in, 1e-3);
  x_d = (m_feed_pos*port_a.x + m_flow_rec*x)/(m_feed_pos + m_flow_rec);
  nu = Functions.kinematicViscosity(x_d, T);
  U_clean = U0_internal*(nu_ref/nu)^n_visc;
  U_eff = 1/(1/U_clean + Rf_internal + dRf_internal);
  p_s = M_steam*R_w*T_ref_steam/V_steam;
  T_s = Saturation.TSat(p_s);
  Q = U_eff*A*(T_s - T);
  h_c = BlackLiquor.specificEnthalpy(0, T_s);
  m_c = Q/(Saturation.hVapour(T_s) - h_c);
  m_vent = ventFraction*m_c;
  m_steam = m_flow_steam_nominal*(steamLeakage + (1 - steamLeakage)*steamOpening)*Functions.regRoot(port_s.p - p_s, dp_steam_small)/sqrt(dp_steam_nominal);
  der(M_steam) = m_steam - m_c - m_vent - m_flow_vent_internal;
  port_s.m_flow = m_steam;
  port_c.m_flow = -m_c;
  port_c.x = 0;
  port_c.T = T_s;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Line(points={{-40,90},{-40,-10}}, color={255,0,0}), Line(points={{0,90},{0,-10}}, color={255,0,0}), Line(points={{40,90},{40,-10}}, color={255,0,0})}), Documentation(info="<html>
<p>The liquor body, vapour space and level are those of
<code>BaseClasses.PartialVessel</code> (states <code>M</code>, <code>M_s</code>,
<code>T</code>, <code>M_vap</code>). The feed mixes with the recirculation
<code>m_flow_rec</code> on top of the tubes; the mixture's dry solids
<code>x_d</code> and the body temperature set the liquor viscosity, and the
clean coefficient is <code>U_clean = U0&middot;(nu_ref/&nu;)^0.41</code>
(falling-film liquor side, evaporator notes section 1). With the fouling
resistance <code>Rf</code> (tunable; or the input <code>Rf_in</code> with
<code>use_Rf_in = true</code>, which is how a generated TrackingBox drives it; <code>U0</code> likewise has
<code>use_U0_in</code>):
<code>U_eff = 1/(1/U_clean + Rf)</code> and
<code>Q = U_eff&middot;A&middot;(T_s - T)</code>.</p>
<p>Steam chest: one state (steam mass <code>M_steam</code>, ideal gas at the
fixed temperature <code>T_ref_steam</code>); steam enters through the effect's
own steam valve (regularised square-root law, opening input
<code>steamOpening</code>), condenses at <code>T_s = TSat(p_s)</code> with
<code>m_c = Q/(hVapour(T_s) - h(0, T_s))</code> and drains at once through
<code>port_c</code> as saturated condensate; a fraction
<code>ventFraction</code> of it is vented (plant leak).</p>
<p>Diagnosis hooks (off by default; off, the internal signals are 0 and the
equations those without them): <code>use_vent_in</code> lets the input
<code>m_flow_vent_in</code> (kg/s) of steam leave the chest uncondensed;
<code>use_dRf_in</code> adds the input <code>dRf_in</code> (m2.K/W) to the
fouling resistance (deposits that behave otherwise than <code>Rf</code>).</p>
</html>"));
end Effect;
