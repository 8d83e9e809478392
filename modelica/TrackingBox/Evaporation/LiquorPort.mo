within TrackingBox.Evaporation;
connector LiquorPort "Liquor (or condensate) port for directed flow"
  TrackingBox.Units.Pressure p "Pressure at the port (piezometric)";
  flow TrackingBox.Units.MassFlowRate m_flow "Mass flow rate from the connection into the component";
  TrackingBox.Units.Fraction x "Dry-solids mass fraction of the liquid flowing in the design direction (0 for condensate)";
  TrackingBox.Units.Temperature T "Temperature of the liquid flowing in the design direction";
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Ellipse(extent={{-100,100},{100,-100}}, lineColor={139,90,43}, fillColor={139,90,43}, fillPattern=FillPattern.Solid)}),
    Documentation(info="<html>
<p>As <code>TrackingBox.Interfaces.FluidPort</code>, with the dry-solids
fraction <code>x</code> as a second potential set by the upstream side. The
enthalpy of the stream is <code>Media.BlackLiquor.specificEnthalpy(x, T)</code>.</p>
</html>"));
end LiquorPort;
