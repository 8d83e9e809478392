within TrackingBox.Fluid.Sources;
model PressureSource "Source with prescribed pressure and temperature"
  parameter TrackingBox.Units.Pressure p = 101325 "Pressure, used when use_p_in = false";
  parameter TrackingBox.Units.Temperature T = 293.15 "Temperature, used when use_T_in = false";
  parameter Boolean use_p_in = false "= true to take the pressure from the input p_in";
  parameter Boolean use_T_in = false "= true to take the temperature from the input T_in";
  TrackingBox.Interfaces.RealInput p_in(unit="Pa") if use_p_in "Pressure"
    annotation (Placement(transformation(extent={{-140,20},{-100,60}})));
  TrackingBox.Interfaces.RealInput T_in(unit="K") if use_T_in "Temperature"
    annotation (Placement(transformation(extent={{-140,-60},{-100,-20}})));
  TrackingBox.Interfaces.FluidPort_b port "Outlet"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
protected
  TrackingBox.Interfaces.RealInput p_internal(unit="Pa") "Used pressure";
  TrackingBox.Interfaces.RealInput T_internal(unit="K") "Used temperature";
equation
  connect(p_in, p_internal);
  connect(T_in, T_internal);
  if not use_p_in then
    p_internal = p;
  end if;
  if not use_T_in then
    T_internal = T;
  end if;
  port.p = p_internal;
  port.T = T_internal;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Ellipse(extent={{-100,100},{100,-100}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.Sphere),
      Text(extent={{-60,40},{60,-40}}, textString="p", textColor={255,255,255}),
      Text(extent={{-150,150},{150,110}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>An infinite reservoir at the absolute pressure <code>p</code> (Pa),
delivering water at the temperature <code>T</code> (K): <code>port.p = p</code>,
<code>port.T = T</code>. The flow is whatever the connected network takes; if
the network pushes water back into the source, it is accepted at the same
<code>T</code> (directed-flow convention of <code>Interfaces.FluidPort</code>).
With <code>use_p_in</code> and <code>use_T_in</code> the values come from the
inputs <code>p_in</code> and <code>T_in</code>.</p>
</html>"));
end PressureSource;
