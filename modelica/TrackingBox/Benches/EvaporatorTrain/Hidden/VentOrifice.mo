within TrackingBox.Benches.EvaporatorTrain.Hidden;
model VentOrifice "Train plant whose effect-1 steam chest vents steam through an orifice (NCG vent left open)"
  extends Clean(effect(each use_vent_in=true));
  parameter Integer kVent(min=1) = 1 "The effect whose chest vents";
  parameter TrackingBox.Units.MassFlowRate mVentRef = 0.015*steamDesign "Vent flow at the reference overpressure (1.5 % of the design live steam)";
  parameter TrackingBox.Units.PressureDifference dpVentRef = 2.5e5 "Reference overpressure of the chest over the vent's outlet";
  parameter TrackingBox.Units.Pressure pVent = 1.0e5 "Pressure the vent discharges to";
  TrackingBox.Interfaces.RealOutput m_vent_orifice[N](each unit="kg/s") "Steam vented through the orifice of each chest (0 but for effect kVent)"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  for k in 1:N loop
    m_vent_orifice[k] = if k == kVent then mVentRef*TrackingBox.Evaporation.Functions.regRoot(effect[k].p_s - pVent, 1000)/sqrt(dpVentRef) else 0;
    connect(m_vent_orifice[k], effect[k].m_flow_vent_in);
  end for;
  annotation (Documentation(info="<html>
<p>Orifice law on the chest of effect <code>kVent</code> (1, the live-steam
effect): <code>m = mVentRef&middot;regRoot(p_s - pVent)/sqrt(dpVentRef)</code>, 1.5 % of
the design live steam at 3.5 bar in the chest, venting even while the steam valve
is closed in a stoppage. The other chests do not vent.</p>
</html>"));
end VentOrifice;
