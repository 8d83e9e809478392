within TrackingBox.Evaporation;
model LiquorValve "Liquor valve: regularised square-root law, linear or equal-percentage characteristic, leakage"
  import TrackingBox.Evaporation.Functions;
  parameter TrackingBox.Units.ValveCoefficient KvMax = 10 "Flow coefficient at full opening (m3/h of water at 1 bar)";
  parameter Boolean use_KvMax_in = false "= true to take KvMax from the input KvMax_in";
  parameter TrackingBox.Units.Factor capacity = 1 "Flow capacity as a fraction of KvMax (wear or deposits; 1: as rated), used when use_capacity_in = false";
  parameter Boolean use_capacity_in = false "= true to take the capacity from the input capacity_in";
  parameter Boolean equalPercentage = false "= true for the equal-percentage characteristic (R^y - 1)/(R - 1), else linear";
  parameter Real R(unit="1", min=2) = 30 "Rangeability of the equal-percentage characteristic";
  parameter TrackingBox.Units.Fraction leakage = 1e-3 "Flow coefficient of the closed valve as a fraction of KvMax";
  parameter TrackingBox.Units.PressureDifference dp_small = 1000 "Below about this pressure difference the law is regularised to linear";
  TrackingBox.Evaporation.LiquorPort_a port_a "Inlet"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  TrackingBox.Evaporation.LiquorPort_b port_b "Outlet"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
  TrackingBox.Interfaces.RealInput opening(unit="1") "Valve opening, 0 (closed) .. 1 (open)"
    annotation (Placement(transformation(origin={0,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput KvMax_in(unit="m3/h") if use_KvMax_in "Flow coefficient from outside"
    annotation (Placement(transformation(origin={-60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput capacity_in(unit="1") if use_capacity_in "Capacity fraction from outside"
    annotation (Placement(transformation(origin={60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Units.MassFlowRate m_flow "Mass flow from port_a to port_b";
  TrackingBox.Units.PressureDifference dp "port_a.p - port_b.p";
  TrackingBox.Units.Fraction f "Characteristic at the opening";
  TrackingBox.Units.Density rho "Liquid density at the inlet";
protected
  TrackingBox.Interfaces.RealInput KvMax_internal(unit="m3/h") "Used flow coefficient";
  TrackingBox.Interfaces.RealInput capacity_internal(unit="1") "Used capacity fraction";
equation
  connect(KvMax_in, KvMax_internal);
  connect(capacity_in, capacity_internal);
  if not use_KvMax_in then
    KvMax_internal = KvMax;
  end if;
  if not use_capacity_in then
    capacity_internal = capacity;
  end if;
  f = if equalPercentage then (exp(opening*log(R)) - 1)/(R - 1) else opening;
  rho = TrackingBox.Media.BlackLiquor.density(port_a.x, port_a.T);
  dp = port_a.p - port_b.p;
  m_flow = capacity_internal*KvMax_internal/3600*(leakage + (1 - leakage)*f)*sqrt(1000*rho/1e5)*Functions.regRoot(dp, dp_small);
  port_a.m_flow = m_flow;
  port_a.m_flow + port_b.m_flow = 0;
  port_b.x = port_a.x;
  port_b.T = port_a.T;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Polygon(points={{-100,50},{0,0},{-100,-50},{-100,50}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid), Polygon(points={{100,50},{0,0},{100,-50},{100,50}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid), Line(points={{0,0},{0,80}}, color={0,0,127}), Text(extent={{-150,-105},{150,-135}}, textString="%name")}), Documentation(info="<html>
<p><code>m_flow = capacity&middot;KvMax/3600&middot;(leakage + (1 - leakage)&middot;f(y))&middot;sqrt(1000&middot;&rho;&middot;&Delta;p/1e5)</code>
(the Kv definition: m3/h of a liquid of specific gravity &rho;/1000 at 1 bar),
with the square root regularised as <code>regRoot(&Delta;p, dp_small)</code>.
Characteristic <code>f = y</code> (linear) or <code>(R^y - 1)/(R - 1)</code>
(equal percentage, shifted so that it closes at <code>y = 0</code>).
<code>capacity</code> (1: as rated) is the valve's wear or deposits as a
fraction of its rated <code>KvMax</code>; a twin tracks it through
<code>use_capacity_in</code> while <code>KvMax</code> keeps the design sizing. The
opening is used as given (the smooth controllers keep it inside 0..1).
Isenthalpic: <code>x</code> and <code>T</code> pass unchanged.</p>
</html>"));
end LiquorValve;
