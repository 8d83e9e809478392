within TrackingBox.Benches.EvaporatorTrain.BaseClasses;
model VapourLine "Vapour line with the regularised square-root law of the vessels' vapour lines"
  parameter TrackingBox.Units.MassFlowRate m_flow_nominal = 2 "Flow at dp_nominal";
  parameter TrackingBox.Units.PressureDifference dp_nominal = 500 "Pressure drop at m_flow_nominal";
  parameter TrackingBox.Units.PressureDifference dp_small = 50 "Regularisation of the square-root law";
  TrackingBox.Interfaces.FluidPort_a port_a "Inlet"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  TrackingBox.Interfaces.FluidPort_b port_b "Outlet"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
  TrackingBox.Units.MassFlowRate m_flow "Flow from port_a to port_b";
equation
  m_flow = m_flow_nominal*TrackingBox.Evaporation.Functions.regRoot(port_a.p - port_b.p, dp_small)/sqrt(dp_nominal);
  port_a.m_flow = m_flow;
  port_a.m_flow + port_b.m_flow = 0;
  port_b.T = port_a.T;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Rectangle(extent={{-100,20},{100,-20}}, lineColor={0,0,0}, fillColor={230,230,255}, fillPattern=FillPattern.Solid), Text(extent={{-150,-25},{150,-55}}, textString="%name")}), Documentation(info="<html>
<p><code>m_flow = m_flow_nominal&middot;regRoot(&Delta;p, dp_small)/sqrt(dp_nominal)</code>,
the law of <code>Evaporation.BaseClasses.PartialVessel</code>'s vapour line;
the temperature passes unchanged.</p>
</html>"));
end VapourLine;
