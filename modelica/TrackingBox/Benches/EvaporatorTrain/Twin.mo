within TrackingBox.Benches.EvaporatorTrain;
model Twin "N-effect evaporator train, digital twin: clean design values, a correction-flow input on every level"
  extends TrackingBox.Benches.EvaporatorTrain.BaseClasses.PartialTrain(useCorrectionInputs=true);
  TrackingBox.Interfaces.RealInput body_m_flow_corr[N](each unit="kg/s", each start=0) "Correction flow into each effect's liquor (state compensation of LI_body[k])"
    annotation (Placement(transformation(origin={-60,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
  TrackingBox.Interfaces.RealInput flash_m_flow_corr(unit="kg/s", start=0) "Correction flow into the product flash tank (state compensation of LI_flash)"
    annotation (Placement(transformation(origin={0,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
  TrackingBox.Interfaces.RealInput cond_m_flow_corr[N](each unit="kg/s", each start=0) "Correction flow into each condensate tank (state compensation of LI_condensate[k])"
    annotation (Placement(transformation(origin={60,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
equation
  for k in 1:N loop
    connect(body_m_flow_corr[k], effect[k].m_flow_corr_in);
    connect(cond_m_flow_corr[k], condTank[k].m_flow_corr_in);
  end for;
  connect(flash_m_flow_corr, flash.m_flow_corr_in);
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Text(extent={{-90,-62},{90,-92}}, textString="twin", textColor={0,0,0})}),
    experiment(StopTime=3600, Tolerance=1e-6), Documentation(info="<html>
<p>Clean design values: no fouling (<code>effect[k].Rf = 0</code>, bounds
0..6e-4 m2.K/W), no boiling-point offsets, vents or heat losses, new valves
and pumps. Tunable per effect: <code>effect[k].Rf</code>,
<code>effect[k].dBPR</code>, <code>effect[k].U0</code>; for the whole train the
steam economy's losses <code>ventFractionAll</code> (steam vented from every chest,
fraction of its condensate) and <code>UA_lossAll</code> (every effect's heat-loss
conductance), constants a modeller calibrates on the data; the valves' wear
<code>capacity</code> and the pumps' <code>head</code> (1: as designed) and the
product pump's <code>dp0</code>, <code>VMax</code>; each with its component's
conditional input for a generated TrackingBox. State
compensation: <code>body_m_flow_corr[k]</code>, <code>flash_m_flow_corr</code>,
<code>cond_m_flow_corr[k]</code> (kg/s, default 0) add liquid at the vessel's
own composition and temperature.</p>
</html>"));
end Twin;
