within TrackingBox.Benches.EvaporatorTrain.BaseClasses;
model VapourPlug "Closed end of an unused vapour inlet"
  parameter TrackingBox.Units.Temperature T = 373.15 "Temperature the closed port reports (no flow carries it)";
  TrackingBox.Interfaces.FluidPort_b port "Closed port"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
equation
  port.m_flow = 0;
  port.T = T;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Rectangle(extent={{-40,60},{40,-60}}, lineColor={0,0,0}, fillColor={0,0,0}, fillPattern=FillPattern.Solid)}), Documentation(info="<html>
<p>No flow; closes an inlet of a <code>VapourHeader</code> that a given header
does not use, so that the headers of a train can be an array of one size.</p>
</html>"));
end VapourPlug;
