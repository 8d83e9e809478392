within TrackingBox.Fluid.Validation;
model CurveLaws "Pipe and pump laws (quadratic, linear secant, linear tangent) over a ramp of flow"
  extends TrackingBox.Icons.Example;
  parameter TrackingBox.Units.MassFlowRate m_flow_nominal = 0.05 "Nominal flow of the pipes";
  parameter TrackingBox.Units.Fraction speed = 0.8 "Relative speed of the pumps";
  parameter TrackingBox.Units.VolumeFlowRate VFlowDesign = 8e-5 "Design flow of the pumps";
  parameter Real rhoNominal(unit="kg/m3") = 988 "Approximate density of the water, for the ramp of the pumps";
  Real ramp(unit="1") "Goes from 0 to 1 over the run";
  // pipes: flow from 0.2 to 1.5 times the nominal flow
  TrackingBox.Fluid.Sources.MassFlowSource srcQ(use_m_flow_in=true, T=323.15);
  TrackingBox.Fluid.Sources.MassFlowSource srcS(use_m_flow_in=true, T=323.15);
  TrackingBox.Fluid.Sources.MassFlowSource srcT(use_m_flow_in=true, T=323.15);
  TrackingBox.Fluid.Pipe pipeQ(quadratic=true, k=0.005, m_flow_nominal=m_flow_nominal) "Quadratic";
  TrackingBox.Fluid.Pipe pipeS(quadratic=false, k=0.005, m_flow_nominal=m_flow_nominal) "Linear, secant";
  TrackingBox.Fluid.Pipe pipeT(quadratic=false, tangent=true, k=0.005, m_flow_nominal=m_flow_nominal) "Linear, tangent";
  TrackingBox.Fluid.Sources.PressureSink sinkQ(p=200000);
  TrackingBox.Fluid.Sources.PressureSink sinkS(p=200000);
  TrackingBox.Fluid.Sources.PressureSink sinkT(p=200000);
  // pumps at fixed speed: flow from 0.2 to 1.5 times the affinity point (x = speed)
  TrackingBox.Fluid.Sources.MassFlowSource srcPQ(use_m_flow_in=true, T=323.15);
  TrackingBox.Fluid.Sources.MassFlowSource srcPS(use_m_flow_in=true, T=323.15);
  TrackingBox.Fluid.Sources.MassFlowSource srcPT(use_m_flow_in=true, T=323.15);
  TrackingBox.Fluid.Pump pumpQ(quadratic=true, use_speed_in=false, speedFixed=speed, VFlowDesign=VFlowDesign, uRise=40000) "Quadratic";
  TrackingBox.Fluid.Pump pumpS(quadratic=false, use_speed_in=false, speedFixed=speed, VFlowDesign=VFlowDesign, uRise=40000) "Linear, secant";
  TrackingBox.Fluid.Pump pumpT(quadratic=false, tangent=true, use_speed_in=false, speedFixed=speed, VFlowDesign=VFlowDesign, uRise=40000) "Linear, tangent";
  TrackingBox.Fluid.Sources.PressureSink sinkPQ(p=200000);
  TrackingBox.Fluid.Sources.PressureSink sinkPS(p=200000);
  TrackingBox.Fluid.Sources.PressureSink sinkPT(p=200000);
equation
  ramp = time/100;
  srcQ.m_flow_in = m_flow_nominal*(0.2 + 1.3*ramp);
  srcS.m_flow_in = m_flow_nominal*(0.2 + 1.3*ramp);
  srcT.m_flow_in = m_flow_nominal*(0.2 + 1.3*ramp);
  srcPQ.m_flow_in = rhoNominal*VFlowDesign*speed*(0.2 + 1.3*ramp);
  srcPS.m_flow_in = rhoNominal*VFlowDesign*speed*(0.2 + 1.3*ramp);
  srcPT.m_flow_in = rhoNominal*VFlowDesign*speed*(0.2 + 1.3*ramp);
  connect(srcQ.port, pipeQ.port_a);
  connect(pipeQ.port_b, sinkQ.port);
  connect(srcS.port, pipeS.port_a);
  connect(pipeS.port_b, sinkS.port);
  connect(srcT.port, pipeT.port_a);
  connect(pipeT.port_b, sinkT.port);
  connect(srcPQ.port, pumpQ.port_a);
  connect(pumpQ.port_b, sinkPQ.port);
  connect(srcPS.port, pumpS.port_a);
  connect(pumpS.port_b, sinkPS.port);
  connect(srcPT.port, pumpT.port_a);
  connect(pumpT.port_b, sinkPT.port);
  annotation (experiment(StopTime=100), Documentation(info="<html>
<p>Each pipe and pump law under the same ramp of flow, so their curves can be
compared: all three agree at the design point (pipes: nominal flow; pumps:
<code>x = speed</code>), the tangents also in slope there.</p>
</html>"));
end CurveLaws;
