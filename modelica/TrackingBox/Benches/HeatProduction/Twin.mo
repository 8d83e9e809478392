within TrackingBox.Benches.HeatProduction;
model Twin "Heat-production process, digital twin: linear curves, initial parameter values, tank correction flows"
  extends TrackingBox.Benches.HeatProduction.BaseClasses.PartialProcess(
    T100(use_m_flow_corr_in=true), T200(use_m_flow_corr_in=true), T400(use_m_flow_corr_in=true));
  TrackingBox.Interfaces.RealInput T100_m_flow_corr(unit="kg/s", start=0) "Correction flow into T100 (state compensation)"
    annotation (Placement(transformation(origin={-60,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
  TrackingBox.Interfaces.RealInput T200_m_flow_corr(unit="kg/s", start=0) "Correction flow into T200 (state compensation)"
    annotation (Placement(transformation(origin={0,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
  TrackingBox.Interfaces.RealInput T400_m_flow_corr(unit="kg/s", start=0) "Correction flow into T400 (state compensation)"
    annotation (Placement(transformation(origin={60,-115}, extent={{-15,-15},{15,15}}, rotation=90)));
equation
  connect(T100_m_flow_corr, T100.m_flow_corr_in);
  connect(T200_m_flow_corr, T200.m_flow_corr_in);
  connect(T400_m_flow_corr, T400.m_flow_corr_in);
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Text(extent={{-90,-62},{90,-92}}, textString="twin", textColor={0,0,0})}),
    Documentation(info="<html>
<p>Linear pipe and pump curves, as the source's twin has them: a pipe's loss
proportional to its flow (<code>dp = dp_ref&middot;k&middot;x</code>, equal to the
plant's quadratic loss at zero and at nominal flow), a pump's curve the chord
from its shut-off point to its design point (equal to the plant's quadratic
curve at both); and the initial parameter values of the method notes.</p>
<p>Not the tangents at the design point: the pumps and pipes run at 55-125 %
of their nominal flow over a day, and at the low-load end a tangent pipe law
<code>dp_ref&middot;k&middot;(2x - 1)</code> hardly depends on <code>k</code>
(at <code>x = 0.6</code>, 0.2 MPa per unit of <code>k</code>, against 0.36 MPa for
the plant and 0.6 MPa for the proportional law), so a step test there found no
pipe coefficient that could close a pressure offset from inside its bounds.
The tangents also predict a pressure gain below half the nominal flow.</p>
<p>For state
compensation each tank takes a correction flow from a top-level input
<code>T100_m_flow_corr</code>, <code>T200_m_flow_corr</code>,
<code>T400_m_flow_corr</code> (kg/s), added to the tunable parameter
<code>T*.m_flow_corr</code> (default 0).</p>
</html>"));
end Twin;
