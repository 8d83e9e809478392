within TrackingBox.Benches.Evaporator;
model Twin "Last-effect slice, digital twin: clean design values, correction-flow inputs for state compensation"
  extends TrackingBox.Benches.Evaporator.BaseClasses.PartialSlice(
    effect(use_m_flow_corr_in=true),
    flash(use_m_flow_corr_in=true),
    condTank(use_m_flow_corr_in=true));
  TrackingBox.Interfaces.RealInput body_m_flow_corr(unit="kg/s", start=0) "Correction flow into the effect's liquor body (state compensation of LI_body)"
    annotation (Placement(transformation(origin={-60,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
  TrackingBox.Interfaces.RealInput flash_m_flow_corr(unit="kg/s", start=0) "Correction flow into the flash tank (state compensation of LI_flash)"
    annotation (Placement(transformation(origin={0,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
  TrackingBox.Interfaces.RealInput cond_m_flow_corr(unit="kg/s", start=0) "Correction flow into the condensate tank (state compensation of LI_condensate)"
    annotation (Placement(transformation(origin={60,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
equation
  connect(body_m_flow_corr, effect.m_flow_corr_in);
  connect(flash_m_flow_corr, flash.m_flow_corr_in);
  connect(cond_m_flow_corr, condTank.m_flow_corr_in);
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Text(extent={{-90,-62},{90,-92}}, textString="twin", textColor={0,0,0})}),
    experiment(StopTime=3600, Tolerance=1e-6), Documentation(info="<html>
<p>Clean design values: no fouling (<code>effect.Rf = 0</code>, bounds
0..6e-4 m2.K/W), no boiling-point offset (<code>effect.dBPR = 0</code>, tunable: the
evaporator notes' &Delta;BPR; tracked on the body temperature it keeps a
composition offset of the real liquor from being read as fouling), no vent,
no heat loss, new valves and pump. Tunable: <code>effect.Rf</code>,
<code>effect.dBPR</code>, <code>effect.U0</code>,
<code>inletValve.KvMax</code>, <code>outletValve.KvMax</code>,
<code>pump.dp0</code>, <code>pump.VMax</code>. State compensation: the inputs
<code>body_m_flow_corr</code>, <code>flash_m_flow_corr</code>,
<code>cond_m_flow_corr</code> (kg/s, default 0) add liquid at the vessel's own
composition and temperature.</p>
</html>"));
end Twin;
