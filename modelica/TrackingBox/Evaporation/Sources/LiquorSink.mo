within TrackingBox.Evaporation.Sources;
model LiquorSink "Liquor reservoir with prescribed pressure receiving liquor"
  parameter TrackingBox.Units.Pressure p = 1e5 "Pressure, used when use_p_in = false";
  parameter Boolean use_p_in = false "= true to take the pressure from the input p_in";
  TrackingBox.Interfaces.RealInput p_in(unit="Pa") if use_p_in "Pressure"
    annotation (Placement(transformation(origin={120,0}, extent={{-20,-20},{20,20}}, rotation=180)));
  TrackingBox.Evaporation.LiquorPort_a port "Inlet"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
protected
  TrackingBox.Interfaces.RealInput p_internal(unit="Pa") "Used pressure";
equation
  connect(p_in, p_internal);
  if not use_p_in then
    p_internal = p;
  end if;
  port.p = p_internal;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Ellipse(extent={{-100,100},{100,-100}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Sphere),
      Text(extent={{-60,40},{60,-40}}, textString="p", textColor={255,255,255}),
      Text(extent={{-150,150},{150,110}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>An infinite reservoir at the absolute pressure <code>p</code> (Pa) receiving
liquor or condensate: <code>port.p = p</code>. The flow is whatever the line
upstream delivers against that back-pressure; <code>x</code> and <code>T</code>
come from upstream. With <code>use_p_in</code> the pressure comes from the
input <code>p_in</code>.</p>
</html>"));
end LiquorSink;
