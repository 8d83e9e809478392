within TrackingBox.Fluid;
model Pipe "Pipe with a quadratic (plant) or linear (twin) pressure loss"
  extends TrackingBox.Interfaces.PartialTwoPort;
  parameter Boolean quadratic = true "= true: pressure loss quadratic in the flow; false: linear";
  parameter Real k(unit="1", min=0) = 0.005 "Dynamic pressure-drop coefficient: pressure loss at m_flow_nominal divided by dp_ref";
  parameter TrackingBox.Units.MassFlowRate m_flow_nominal(min=1e-6) = 0.07 "Nominal mass flow rate";
  parameter TrackingBox.Units.PressureDifference dp_ref = 1e6 "Reference pressure difference of k";
  parameter Boolean use_k_in = false "= true to take k from the input k_in";
  TrackingBox.Interfaces.RealInput k_in(unit="1") if use_k_in "Pressure-drop coefficient from outside";
  Real x(unit="1") "Relative flow m_flow/m_flow_nominal";
protected
  TrackingBox.Interfaces.RealInput k_internal(unit="1") "Used pressure-drop coefficient";
equation
  connect(k_in, k_internal);
  if not use_k_in then
    k_internal = k;
  end if;
  x = m_flow/m_flow_nominal;
  if quadratic then
    dp = dp_ref*k_internal*x*noEvent(abs(x));
  else
    dp = dp_ref*k_internal*x;
  end if;
  port_b.T = port_a.T;
  annotation (Documentation(info="<html>
<p><code>dp = dp_ref&middot;k&middot;x&middot;|x|</code> (quadratic) or
<code>dp = dp_ref&middot;k&middot;x</code> (linear), <code>x = m_flow/m_flow_nominal</code>.
With the default <code>dp_ref = 1 MPa</code>, <code>k = 0.005</code> is a
5 kPa loss at nominal flow. Both laws agree at nominal flow. No heat loss,
no storage.</p>
</html>"));
end Pipe;
