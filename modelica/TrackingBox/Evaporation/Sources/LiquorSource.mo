within TrackingBox.Evaporation.Sources;
model LiquorSource "Liquor reservoir with prescribed pressure, temperature and dry solids"
  parameter TrackingBox.Units.Pressure p = 3e5 "Pressure, used when use_p_in = false";
  parameter TrackingBox.Units.Temperature T = 368.15 "Temperature, used when use_T_in = false";
  parameter TrackingBox.Units.Fraction x = 0.52 "Dry-solids fraction, used when use_x_in = false";
  parameter Boolean use_p_in = false "= true to take the pressure from the input p_in";
  parameter Boolean use_T_in = false "= true to take the temperature from the input T_in";
  parameter Boolean use_x_in = false "= true to take the dry-solids fraction from the input x_in";
  TrackingBox.Interfaces.RealInput p_in(unit="Pa") if use_p_in "Pressure";
  TrackingBox.Interfaces.RealInput T_in(unit="K") if use_T_in "Temperature";
  TrackingBox.Interfaces.RealInput x_in(unit="1") if use_x_in "Dry-solids fraction";
  TrackingBox.Evaporation.LiquorPort_b port "Outlet";
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
  annotation (Documentation(info="<html><p>Infinite liquor reservoir at pressure <code>p</code> delivering liquor at <code>T</code> and <code>x</code>.</p></html>"));
end LiquorSource;
