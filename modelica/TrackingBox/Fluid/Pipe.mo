within TrackingBox.Fluid;
model Pipe "Pipe with a quadratic (plant) or linear (twin) pressure loss"
  extends TrackingBox.Interfaces.PartialTwoPort;
  parameter Boolean quadratic = true "= true: pressure loss quadratic in the flow; false: linear";
  parameter Boolean tangent = false "Linear law only: = true: tangent of the quadratic law at m_flow_nominal (forward flow near nominal); false: secant through zero flow";
  parameter TrackingBox.Units.Factor k = 0.005 "Dynamic pressure-drop coefficient: pressure loss at m_flow_nominal divided by dp_ref";
  parameter TrackingBox.Units.MassFlowRate m_flow_nominal(min=1e-6) = 0.07 "Nominal mass flow rate";
  parameter TrackingBox.Units.PressureDifference dp_ref = 1e6 "Reference pressure difference of k";
  parameter Boolean use_k_in = false "= true to take k from the input k_in";
  TrackingBox.Interfaces.RealInput k_in(unit="1") if use_k_in "Pressure-drop coefficient from outside"
    annotation (Placement(transformation(origin={0,120}, extent={{-20,-20},{20,20}}, rotation=270)));
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
  elseif tangent then
    dp = dp_ref*k_internal*(2*x - 1);
  else
    dp = dp_ref*k_internal*x;
  end if;
  port_b.T = port_a.T;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Rectangle(extent={{-100,30},{100,-30}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.HorizontalCylinder),
      Text(extent={{-150,-40},{150,-80}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p><code>dp = dp_ref&middot;k&middot;x&middot;|x|</code> (quadratic) or
<code>dp = dp_ref&middot;k&middot;x</code> (linear), <code>x = m_flow/m_flow_nominal</code>.
With <code>tangent = true</code> the linear law is instead the tangent of the
quadratic one at nominal flow, <code>dp = dp_ref&middot;k&middot;(2x - 1)</code>:
the same loss and slope there, so a twin linearised at its operating point. It
is meant for forward flow near nominal: below half the nominal flow it would
give a pressure gain, and its sensitivity to <code>k</code>,
<code>dp_ref&middot;(2x - 1)</code>, falls faster than the quadratic law's
<code>dp_ref&middot;x&sup2;</code>: at <code>x = 0.6</code> it is 0.2&middot;<code>dp_ref</code>,
against 0.36&middot;<code>dp_ref</code> (quadratic) and 0.6&middot;<code>dp_ref</code> (linear).
With the default <code>dp_ref = 1 MPa</code>, <code>k = 0.005</code> is a
5 kPa loss at nominal flow. Both laws agree at nominal flow. No heat loss,
no storage.</p>
</html>"));
end Pipe;
