within TrackingBox.Benches.Evaporator.Hidden;
model FlashDemister "Evaporator plant whose flash-tank demister is clogged (its resistance grows with its load)"
  extends Clean(flash(use_vapourCapacity_in=true));
  parameter Real phi0(unit="1") = 0.6 "Capacity of the clogged line at no load (fraction of its design law)";
  parameter Real kLoad(unit="s/kg") = 4 "Loss of capacity per kg/s the line would pass by its design law";
  TrackingBox.Interfaces.RealOutput capacity(unit="1") "Capacity of the flash vapour line"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  // the design law's flow at the actual pressure drop, and the clogged line's fraction of it
  capacity = phi0/(1 + kLoad*flash.m_flow_vap_nominal*TrackingBox.Evaporation.Functions.regRoot(flash.p_vap - flash.port_v.p, flash.dp_vap_small)/sqrt(flash.dp_vap_nominal));
  connect(capacity, flash.vapourCapacity_in);
  annotation (Documentation(info="<html>
<p>The flow is <code>phi(L)&middot;L</code> with <code>L</code> the design law at
the actual pressure drop and <code>phi = phi0/(1 + kLoad&middot;L)</code>: about
half the design capacity at the flash's 50 g/s.</p>
</html>"));
end FlashDemister;
