within TrackingBox.Fluid.Sources;
model PressureSource "Source with prescribed pressure and temperature"
  parameter TrackingBox.Units.Pressure p = 101325 "Pressure, used when use_p_in = false";
  parameter TrackingBox.Units.Temperature T = 293.15 "Temperature, used when use_T_in = false";
  parameter Boolean use_p_in = false "= true to take the pressure from the input p_in";
  parameter Boolean use_T_in = false "= true to take the temperature from the input T_in";
  TrackingBox.Interfaces.RealInput p_in(unit="Pa") if use_p_in "Pressure";
  TrackingBox.Interfaces.RealInput T_in(unit="K") if use_T_in "Temperature";
  TrackingBox.Interfaces.FluidPort_b port "Outlet";
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
  annotation (Documentation(info="<html><p>Infinite reservoir at pressure <code>p</code>, delivering water at <code>T</code>.</p></html>"));
end PressureSource;
