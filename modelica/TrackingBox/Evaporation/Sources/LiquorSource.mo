within TrackingBox.Evaporation.Sources;
model LiquorSource "Liquor reservoir with prescribed pressure, temperature and dry solids"
  parameter TrackingBox.Units.Pressure p = 3e5 "Pressure, used when use_p_in = false";
  parameter TrackingBox.Units.Temperature T = 368.15 "Temperature, used when use_T_in = false";
  parameter TrackingBox.Units.Fraction x = 0.52 "Dry-solids fraction, used when use_x_in = false";
  parameter Boolean use_p_in = false "= true to take the pressure from the input p_in";
  parameter Boolean use_T_in = false "= true to take the temperature from the input T_in";
  parameter Boolean use_x_in = false "= true to take the dry-solids fraction from the input x_in";
  TrackingBox.Interfaces.RealInput p_in(unit="Pa") if use_p_in "Pressure"
    annotation (Placement(transformation(extent={{-140,40},{-100,80}})));
  TrackingBox.Interfaces.RealInput T_in(unit="K") if use_T_in "Temperature"
    annotation (Placement(transformation(extent={{-140,-20},{-100,20}})));
  TrackingBox.Interfaces.RealInput x_in(unit="1") if use_x_in "Dry-solids fraction"
    annotation (Placement(transformation(extent={{-140,-80},{-100,-40}})));
  TrackingBox.Evaporation.LiquorPort_b port "Outlet"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
protected
  TrackingBox.Interfaces.RealInput p_internal(unit="Pa") "Used pressure";
  TrackingBox.Interfaces.RealInput T_internal(unit="K") "Used temperature";
  TrackingBox.Interfaces.RealInput x_internal(unit="1") "Used dry-solids fraction";
equation
  connect(p_in, p_internal);
  connect(T_in, T_internal);
  connect(x_in, x_internal);
  if not use_p_in then
    p_internal = p;
  end if;
  if not use_T_in then
    T_internal = T;
  end if;
  if not use_x_in then
    x_internal = x;
  end if;
  port.p = p_internal;
  port.T = T_internal;
  port.x = x_internal;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Ellipse(extent={{-100,100},{100,-100}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Sphere),
      Text(extent={{-60,40},{60,-40}}, textString="p", textColor={255,255,255}),
      Text(extent={{-150,150},{150,110}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>An infinite liquor reservoir at the absolute pressure <code>p</code> (Pa)
delivering liquor at the temperature <code>T</code> (K) and the dry-solids
mass fraction <code>x</code> (1): <code>port.p = p</code>, <code>port.T = T</code>,
<code>port.x = x</code>. The flow is set by the valves and pumps downstream (in
the benches the feed valve's flow loop). With <code>use_p_in</code>,
<code>use_T_in</code> and <code>use_x_in</code> the values come from the inputs
<code>p_in</code>, <code>T_in</code> and <code>x_in</code> (the benches take the
feed's temperature and dry solids from their top-level inputs).</p>
</html>"));
end LiquorSource;
