within TrackingBox.Benches.Evaporator.Hidden;
model MeterAndDemister "Evaporator plant with two effects on different units: a density-based DS meter and a clogged flash demister"
  extends DensityMeter(flash(use_vapourCapacity_in=true));
  parameter Real phi0(unit="1") = 0.6 "Capacity of the clogged line at no load (fraction of its design law)";
  parameter Real kLoad(unit="s/kg") = 4 "Loss of capacity per kg/s the line would pass by its design law";
  TrackingBox.Interfaces.RealOutput capacity(unit="1") "Capacity of the flash vapour line"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  capacity = phi0/(1 + kLoad*flash.m_flow_vap_nominal*TrackingBox.Evaporation.Functions.regRoot(flash.p_vap - flash.port_v.p, flash.dp_vap_small)/sqrt(flash.dp_vap_nominal));
  connect(capacity, flash.vapourCapacity_in);
  annotation (Documentation(info="<html>
<p><code>DensityMeter</code> and the clogged demister of <code>FlashDemister</code>
at once (two effects on different units).</p>
</html>"));
end MeterAndDemister;
