within TrackingBox.Evaporation.Sources;
model LiquorSink "Liquor reservoir with prescribed pressure receiving liquor"
  parameter TrackingBox.Units.Pressure p = 1e5 "Pressure, used when use_p_in = false";
  parameter Boolean use_p_in = false "= true to take the pressure from the input p_in";
  TrackingBox.Interfaces.RealInput p_in(unit="Pa") if use_p_in "Pressure";
  TrackingBox.Evaporation.LiquorPort_a port "Inlet";
protected
  TrackingBox.Interfaces.RealInput p_internal(unit="Pa") "Used pressure";
equation
  connect(p_in, p_internal);
  if not use_p_in then
    p_internal = p;
  end if;
  port.p = p_internal;
  annotation (Documentation(info="<html><p>Infinite reservoir at pressure <code>p</code> receiving liquor.</p></html>"));
end LiquorSink;
