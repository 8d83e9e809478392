within TrackingBox.Evaporation;
model FlashTank "Flash tank: the liquor flashes to the tank's boiling point; the vapour leaves through a vapour line"
  extends TrackingBox.Evaporation.BaseClasses.PartialVessel(
    A_sump=2, V_hold=0.2, H=3, z_out=2, V_vap=4, T_ref_vap=373.15,
    m_flow_vap_nominal=0.2, dp_vap_nominal=3000, K_ev=2,
    x_start=0.78, T_start=393, L_start=1.0, p_start=1.02e5);
equation
  Q = 0;
  annotation (Documentation(info="<html>
<p><code>BaseClasses.PartialVessel</code> without heating: the inflow, hotter
than the tank's boiling point <code>TSat(p_vap) + BPR(x, p_vap)</code>, flashes
(<code>m_ev = K_ev&middot;s&#8314;(T - T_b)</code>). At steady state the flash fraction
is about <code>cp&middot;(T_in - T_b)/h_fg</code> and the outlet dry solids
<code>x_in/(1 - &phi;)</code>.</p>
</html>"));
end FlashTank;
