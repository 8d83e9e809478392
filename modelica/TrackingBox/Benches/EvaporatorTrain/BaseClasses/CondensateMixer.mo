within TrackingBox.Benches.EvaporatorTrain.BaseClasses;
model CondensateMixer "Adiabatic junction of two condensate streams (no volume)"
  parameter TrackingBox.Units.MassFlowRate m_flow_small = 1e-4 "Regularisation of the mixing weights near zero flow";
  TrackingBox.Evaporation.LiquorPort_a port_a1 "First inlet"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  TrackingBox.Evaporation.LiquorPort_a port_a2 "Second inlet"
    annotation (Placement(transformation(extent={{-10,-110},{10,-90}})));
  TrackingBox.Evaporation.LiquorPort_b port_b "Outlet"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
  TrackingBox.Units.MassFlowRate w1 "Mixing weight of the first inlet (its flow, kept positive)";
  TrackingBox.Units.MassFlowRate w2 "Mixing weight of the second inlet (its flow, kept positive)";
equation
  port_a1.p = port_b.p;
  port_a2.p = port_b.p;
  port_a1.m_flow + port_a2.m_flow + port_b.m_flow = 0;
  w1 = TrackingBox.Evaporation.Functions.splus(port_a1.m_flow, m_flow_small);
  w2 = TrackingBox.Evaporation.Functions.splus(port_a2.m_flow, m_flow_small);
  port_b.x = (w1*port_a1.x + w2*port_a2.x)/(w1 + w2);
  port_b.T = (w1*port_a1.T + w2*port_a2.T)/(w1 + w2);
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Ellipse(extent={{-30,30},{30,-30}}, lineColor={0,0,0}, fillColor={0,0,0}, fillPattern=FillPattern.Solid), Line(points={{-100,0},{100,0}}), Line(points={{0,-100},{0,0}}), Text(extent={{-150,-35},{150,-65}}, textString="%name")}), Documentation(info="<html>
<p>The streams merge at the outlet's pressure; the outlet's dry solids and
temperature are flow-weighted means. The enthalpy of
<code>Media.BlackLiquor.specificEnthalpy(0, T)</code> is linear in
<code>T</code>, so for condensate (<code>x = 0</code>) the weighted temperature
conserves energy exactly while both flows are well above
<code>m_flow_small</code>. Mass and dry solids are conserved exactly (the
weights only choose the outlet's potentials).</p>
</html>"));
end CondensateMixer;
