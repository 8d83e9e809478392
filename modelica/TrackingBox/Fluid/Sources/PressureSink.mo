within TrackingBox.Fluid.Sources;
model PressureSink "Sink with prescribed pressure"
  parameter TrackingBox.Units.Pressure p = 101325 "Pressure, used when use_p_in = false";
  parameter Boolean use_p_in = false "= true to take the pressure from the input p_in";
  TrackingBox.Interfaces.RealInput p_in(unit="Pa") if use_p_in "Pressure";
  TrackingBox.Interfaces.FluidPort_a port "Inlet";
  TrackingBox.Units.Temperature T "Temperature of the water received";
protected
  TrackingBox.Interfaces.RealInput p_internal(unit="Pa") "Used pressure";
equation
  connect(p_in, p_internal);
  if not use_p_in then
    p_internal = p;
  end if;
  port.p = p_internal;
  T = port.T;
  annotation (Documentation(info="<html><p>Infinite reservoir at pressure <code>p</code> receiving water.</p></html>"));
end PressureSink;
