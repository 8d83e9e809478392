within TrackingBox.Evaporation;
model CondensateTank "Condensate tank: condensate (x = 0) flashes to the saturation temperature of the tank"
  extends TrackingBox.Evaporation.BaseClasses.PartialVessel(
    A_sump=1, V_hold=0.1, H=2, z_out=1, V_vap=1, T_ref_vap=383.15,
    m_flow_vap_nominal=0.1, dp_vap_nominal=2000, K_ev=2,
    x_start=0, T_start=383, L_start=0.8, p_start=1.42e5);
equation
  Q = 0;
  annotation (Documentation(info="<html>
<p><code>BaseClasses.PartialVessel</code> for condensate: the inflow has
<code>x = 0</code>, so the boiling point is the saturation temperature and
<code>m_ev</code> is the condensate flash
(about <code>m_c&middot;c_w&middot;(T_s - TSat(p))/h_fg</code> at steady state); its vapour
leaves through the vapour line (towards the next steam chest).</p>
</html>"));
end CondensateTank;
