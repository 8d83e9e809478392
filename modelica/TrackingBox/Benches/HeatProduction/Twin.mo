within TrackingBox.Benches.HeatProduction;
model Twin "Heat-production process, digital twin: linear curves, initial parameter values, tank correction flows"
  extends TrackingBox.Benches.HeatProduction.BaseClasses.PartialProcess(
    T100(use_m_flow_corr_in=true), T200(use_m_flow_corr_in=true), T400(use_m_flow_corr_in=true));
  TrackingBox.Interfaces.RealInput T100_m_flow_corr(unit="kg/s", start=0) "Correction flow into T100 (state compensation)";
  TrackingBox.Interfaces.RealInput T200_m_flow_corr(unit="kg/s", start=0) "Correction flow into T200 (state compensation)";
  TrackingBox.Interfaces.RealInput T400_m_flow_corr(unit="kg/s", start=0) "Correction flow into T400 (state compensation)";
equation
  connect(T100_m_flow_corr, T100.m_flow_corr_in);
  connect(T200_m_flow_corr, T200.m_flow_corr_in);
  connect(T400_m_flow_corr, T400.m_flow_corr_in);
  annotation (Documentation(info="<html>
<p>Linear pipe and pump curves (the tangents of the plant's quadratic curves
at the design point: same pressure and slope there, wrong by the curvature away
from it) and the initial parameter values of the method notes. For state
compensation each tank takes a correction flow from a top-level input
<code>T100_m_flow_corr</code>, <code>T200_m_flow_corr</code>,
<code>T400_m_flow_corr</code> (kg/s), added to the tunable parameter
<code>T*.m_flow_corr</code> (default 0).</p>
</html>"));
end Twin;
