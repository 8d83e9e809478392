within TrackingBox.Fluid;
model Pump "Centrifugal pump with speed input and a quadratic (plant) or linear (twin) curve"
  extends TrackingBox.Interfaces.PartialTwoPort;
  parameter Boolean quadratic = true "= true: quadratic pump curve; false: linear";
  parameter Boolean tangent = false "Linear curve only: = true: tangent of the quadratic curve at x = s; false: secant through the shut-off point";
  parameter TrackingBox.Units.PositiveVolumeFlowRate VFlowDesign = 6.6e-5 "Design volume flow rate at nominal speed";
  parameter TrackingBox.Units.PressureRise uRise = 40000 "Pressure rise at design flow and nominal speed";
  parameter Real shutOffRatio(unit="1", min=1.01) = 1.5 "Pressure rise at zero flow divided by uRise";
  parameter TrackingBox.Units.Fraction speedMinLinear = 0.1 "Lowest speed used in the flow term of the linear curve";
  parameter Boolean use_VFlowDesign_in = false "= true to take VFlowDesign from the input VFlowDesign_in";
  parameter Boolean use_uRise_in = false "= true to take uRise from the input uRise_in";
  parameter Boolean use_speed_in = true "= true to take the speed from the input speed";
  parameter TrackingBox.Units.Fraction speedFixed = 1 "Relative speed used when use_speed_in = false";
  TrackingBox.Interfaces.RealInput VFlowDesign_in(unit="m3/s") if use_VFlowDesign_in "Design volume flow rate from outside"
    annotation (Placement(transformation(origin={-60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput uRise_in(unit="Pa") if use_uRise_in "Design pressure rise from outside"
    annotation (Placement(transformation(origin={60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput speed(unit="1") if use_speed_in "Relative speed (1 = nominal)"
    annotation (Placement(transformation(origin={0,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Units.VolumeFlowRate V_flow "Volume flow rate";
  Real x(unit="1") "Relative flow V_flow/VFlowDesign";
  TrackingBox.Units.Fraction s "Relative speed, not below zero";
  TrackingBox.Units.PressureDifference dpRise "Pressure rise port_b.p - port_a.p";
protected
  TrackingBox.Interfaces.RealInput VFlowDesign_internal(unit="m3/s") "Used design flow";
  TrackingBox.Interfaces.RealInput uRise_internal(unit="Pa") "Used design pressure rise";
  TrackingBox.Interfaces.RealInput speed_internal(unit="1") "Used speed";
equation
  connect(VFlowDesign_in, VFlowDesign_internal);
  connect(uRise_in, uRise_internal);
  connect(speed, speed_internal);
  if not use_VFlowDesign_in then
    VFlowDesign_internal = VFlowDesign;
  end if;
  if not use_uRise_in then
    uRise_internal = uRise;
  end if;
  if not use_speed_in then
    speed_internal = speedFixed;
  end if;
  V_flow = m_flow/TrackingBox.Media.Water.rho(port_a.T);
  x = V_flow/VFlowDesign_internal;
  s = noEvent(max(speed_internal, 0));
  dpRise = -dp;
  if quadratic then
    dpRise = uRise_internal*(shutOffRatio*s^2 - (shutOffRatio - 1)*x*noEvent(abs(x)));
  elseif tangent then
    dpRise = uRise_internal*((2*shutOffRatio - 1)*s^2 - 2*(shutOffRatio - 1)*noEvent(max(s, speedMinLinear))*x);
  else
    dpRise = uRise_internal*(shutOffRatio*s^2 - (shutOffRatio - 1)*noEvent(max(s, speedMinLinear))*x);
  end if;
  port_b.T = port_a.T;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Ellipse(extent={{-60,60},{60,-60}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.Sphere),
      Polygon(points={{-30,40},{50,0},{-30,-40},{-30,40}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid),
      Line(points={{0,60},{0,100}}, color={0,0,127}),
      Text(extent={{-150,-70},{150,-110}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Curve through the design point (<code>VFlowDesign</code>, <code>uRise</code>)
at nominal speed, scaled by the affinity laws (<code>x = V_flow/VFlowDesign</code>,
speed <code>s</code>, <code>r = shutOffRatio</code>):</p>
<ul>
<li>quadratic: <code>dp = uRise&middot;(r&middot;s&sup2; - (r-1)&middot;x&sup2;)</code>,
through the shut-off point (0, <code>r&middot;uRise</code>);</li>
<li>linear (<code>tangent = false</code>): <code>dp = uRise&middot;(r&middot;s&sup2; - (r-1)&middot;s&middot;x)</code>,
the secant through the shut-off point and the affinity point <code>x = s</code>;</li>
<li>linear (<code>tangent = true</code>): <code>dp = uRise&middot;((2r-1)&middot;s&sup2; - 2(r-1)&middot;s&middot;x)</code>,
the tangent of the quadratic curve at <code>x = s</code>: the same head and the
same slope there (a linear model fitted at the operating point).</li>
</ul>
<p>The linear flow terms use at least <code>speedMinLinear</code>, so a stopped
pump still resists flow. The medium temperature is not changed.</p>
</html>"));
end Pump;
