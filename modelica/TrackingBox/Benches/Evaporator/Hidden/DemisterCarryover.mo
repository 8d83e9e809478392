within TrackingBox.Benches.Evaporator.Hidden;
model DemisterCarryover "Evaporator plant whose effect demister has failed: liquor droplets leave with the vapour"
  extends Clean(effect(use_entrainment_in=true));
  parameter Real c(unit="s/kg") = 0.012 "Carry-over per kg/s of evaporation, as a fraction of it";
  TrackingBox.Interfaces.RealOutput m_carry(unit="kg/s") "Liquor carried over with the vapour"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  // the carry-over grows with the vapour velocity: the fraction rises with the evaporation
  m_carry = c*effect.m_ev*effect.m_ev;
  connect(m_carry, effect.m_flow_entrain_in);
  annotation (Documentation(info="<html>
<p>Carry-over growing with the square of the evaporation (the droplets' drag):
<code>c&middot;m_ev&sup2;</code>, 5 g/s (0.8 % of the evaporation) at 0.65 kg/s.</p>
</html>"));
end DemisterCarryover;
