within TrackingBox.Fluid;
model Valve "Valve with linear characteristic and flow capacity KvMax"
  extends TrackingBox.Interfaces.PartialTwoPort;
  parameter TrackingBox.Units.ValveCoefficient KvMax = 1 "Flow coefficient at full opening";
  parameter Boolean use_KvMax_in = false "= true to take KvMax from the input KvMax_in";
  parameter Boolean use_opening_in = true "= true to take the opening from the input opening";
  parameter TrackingBox.Units.Fraction openingFixed = 1 "Opening used when use_opening_in = false";
  parameter TrackingBox.Units.Fraction leakage = 1e-4 "Flow coefficient of the closed valve as a fraction of KvMax";
  parameter TrackingBox.Units.PressureDifference dp_small = 100 "Below about this pressure difference the flow is regularised to linear";
  TrackingBox.Interfaces.RealInput KvMax_in(unit="m3/h") if use_KvMax_in "Flow coefficient from outside"
    annotation (Placement(transformation(origin={-60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput opening(unit="1") if use_opening_in "Valve opening, 0 (closed) .. 1 (open)"
    annotation (Placement(transformation(origin={0,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Units.Fraction y "Opening, clipped to 0..1";
  TrackingBox.Units.Density rho "Density at the inlet";
protected
  TrackingBox.Interfaces.RealInput KvMax_internal(unit="m3/h") "Used flow coefficient";
  TrackingBox.Interfaces.RealInput opening_internal(unit="1") "Used opening";
equation
  connect(KvMax_in, KvMax_internal);
  connect(opening, opening_internal);
  if not use_KvMax_in then
    KvMax_internal = KvMax;
  end if;
  if not use_opening_in then
    opening_internal = openingFixed;
  end if;
  y = noEvent(min(max(opening_internal, 0), 1));
  rho = TrackingBox.Media.Water.rho(port_a.T);
  m_flow = rho/3600*KvMax_internal*(leakage + (1 - leakage)*y)*dp/sqrt(sqrt(dp^2 + dp_small^2))/sqrt(1e5);
  port_b.T = port_a.T;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Polygon(points={{-100,50},{0,0},{-100,-50},{-100,50}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.Solid),
      Polygon(points={{100,50},{0,0},{100,-50},{100,50}}, lineColor={0,0,0}, fillColor={0,127,255}, fillPattern=FillPattern.Solid),
      Line(points={{0,0},{0,100}}, color={0,0,127}),
      Text(extent={{-150,-60},{150,-100}}, textString="%name", textColor={0,0,255})}),
    Documentation(info="<html>
<p>Volume flow in m3/h is <code>Kv&middot;sqrt(dp/1 bar)</code> with
<code>Kv = KvMax&middot;(leakage + (1 - leakage)&middot;y)</code>; the square root is
regularised as <code>dp/(dp&sup2; + dp_small&sup2;)^(1/4)</code>.</p>
</html>"));
end Valve;
