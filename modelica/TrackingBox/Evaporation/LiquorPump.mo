within TrackingBox.Evaporation;
model LiquorPump "Centrifugal liquor pump with a quadratic curve"
  parameter TrackingBox.Units.PressureRise dp0 = 4e5 "Pressure rise at zero flow";
  parameter TrackingBox.Units.PositiveVolumeFlowRate VMax = 3e-3 "Volume flow at zero pressure rise";
  parameter TrackingBox.Units.Factor head = 1 "Shut-off pressure rise as a fraction of dp0 (wear; 1: as rated), used when use_head_in = false";
  parameter Boolean use_dp0_in = false "= true to take dp0 from the input dp0_in";
  parameter Boolean use_head_in = false "= true to take the head fraction from the input head_in";
  parameter Boolean use_VMax_in = false "= true to take VMax from the input VMax_in";
  TrackingBox.Evaporation.LiquorPort_a port_a "Suction"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  TrackingBox.Evaporation.LiquorPort_b port_b "Discharge"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
  TrackingBox.Interfaces.RealInput dp0_in(unit="Pa") if use_dp0_in "Shut-off pressure rise from outside"
    annotation (Placement(transformation(origin={-60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput VMax_in(unit="m3/s") if use_VMax_in "Maximum volume flow from outside"
    annotation (Placement(transformation(origin={0,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Interfaces.RealInput head_in(unit="1") if use_head_in "Head fraction from outside"
    annotation (Placement(transformation(origin={60,120}, extent={{-20,-20},{20,20}}, rotation=270)));
  TrackingBox.Units.MassFlowRate m_flow "Mass flow from suction to discharge";
  TrackingBox.Units.VolumeFlowRate V_flow "Volume flow";
  TrackingBox.Units.PressureDifference dp "Pressure rise port_b.p - port_a.p";
  TrackingBox.Units.Density rho "Liquid density";
protected
  TrackingBox.Interfaces.RealInput dp0_internal(unit="Pa") "Used shut-off pressure rise";
  TrackingBox.Interfaces.RealInput VMax_internal(unit="m3/s") "Used maximum volume flow";
  TrackingBox.Interfaces.RealInput head_internal(unit="1") "Used head fraction";
equation
  connect(dp0_in, dp0_internal);
  connect(VMax_in, VMax_internal);
  connect(head_in, head_internal);
  if not use_dp0_in then
    dp0_internal = dp0;
  end if;
  if not use_VMax_in then
    VMax_internal = VMax;
  end if;
  if not use_head_in then
    head_internal = head;
  end if;
  rho = TrackingBox.Media.BlackLiquor.density(port_a.x, port_a.T);
  V_flow = m_flow/rho;
  dp = port_b.p - port_a.p;
  dp = head_internal*dp0_internal*(1 - (V_flow/VMax_internal)^2);
  port_a.m_flow = m_flow;
  port_a.m_flow + port_b.m_flow = 0;
  port_b.x = port_a.x;
  port_b.T = port_a.T;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Ellipse(extent={{-80,80},{80,-80}}, lineColor={0,0,0}, fillColor={255,255,255}, fillPattern=FillPattern.Solid), Polygon(points={{-40,60},{70,0},{-40,-60},{-40,60}}, lineColor={0,0,0}, fillColor={139,90,43}, fillPattern=FillPattern.Solid), Text(extent={{-150,-105},{150,-135}}, textString="%name")}), Documentation(info="<html>
<p><code>&Delta;p = head&middot;dp0&middot;(1 - (V/VMax)&sup2;)</code> at constant speed (the form
of the thesis's <code>uRise</code>/<code>VFlowDesign</code> curve); <code>head</code>
(1: as rated) is the impeller's wear as a fraction of the rated <code>dp0</code>, which a
twin tracks through <code>use_head_in</code> while <code>dp0</code> keeps the design sizing. The
pump's work is neglected in the energy balance (x and T pass unchanged).</p>
</html>"));
end LiquorPump;
