within TrackingBox.Benches.Evaporator.Hidden;
model VentOrifice "Evaporator plant whose steam chest vents steam through an orifice (NCG vent left open)"
  extends Clean(effect(use_vent_in=true));
  parameter TrackingBox.Units.MassFlowRate mVentRef = 0.011 "Vent flow at the reference overpressure";
  parameter TrackingBox.Units.PressureDifference dpVentRef = 2.5e5 "Reference overpressure of the chest over the vent's outlet";
  parameter TrackingBox.Units.Pressure pVent = 1.0e5 "Pressure the vent discharges to";
  TrackingBox.Interfaces.RealOutput m_vent_orifice(unit="kg/s") "Steam vented through the orifice"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  m_vent_orifice = mVentRef*TrackingBox.Evaporation.Functions.regRoot(effect.p_s - pVent, 1000)/sqrt(dpVentRef);
  connect(m_vent_orifice, effect.m_flow_vent_in);
  annotation (Documentation(info="<html>
<p>Orifice law: <code>m = mVentRef&middot;regRoot(p_s - pVent)/sqrt(dpVentRef)</code>,
11 g/s at the chest's 3.5 bar (about 1.5 % of the steam), venting even while the
steam valve is closed in a stoppage.</p>
</html>"));
end VentOrifice;
