within TrackingBox.Benches.Evaporator.Hidden;
model VentOrifice "Evaporator plant whose steam chest vents steam through an orifice (NCG vent left open)"
  extends Clean(effect(use_vent_in=true));
  parameter Real cVent(unit="kg/(s.Pa0.5)") = 2.2e-5 "Orifice constant: vent flow per square root of the chest's overpressure";
  parameter TrackingBox.Units.Pressure pVent = 1.0e5 "Pressure the vent discharges to";
  TrackingBox.Interfaces.RealOutput m_vent_orifice(unit="kg/s") "Steam vented through the orifice";
equation
  m_vent_orifice = cVent*TrackingBox.Evaporation.Functions.regRoot(effect.p_s - pVent, 1000);
  connect(m_vent_orifice, effect.m_flow_vent_in);
  annotation (Documentation(info="<html>
<p>Critical-free orifice: <code>m = cVent&middot;regRoot(p_s - pVent)</code>,
about 11 g/s at the chest's 3.5 bar (1.5 % of the steam), venting even while the
steam valve is closed in a stoppage.</p>
</html>"));
end VentOrifice;
