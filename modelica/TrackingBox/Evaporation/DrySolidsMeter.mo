within TrackingBox.Evaporation;
model DrySolidsMeter "Dry-solids meter on a liquor line, with bias and drift"
  parameter TrackingBox.Units.Fraction bias = 0 "Constant bias";
  parameter TrackingBox.Units.FractionRate drift = 0 "Drift rate of the bias (plant)";
  TrackingBox.Evaporation.LiquorPort_a port "Measuring point (no flow)"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  TrackingBox.Interfaces.RealOutput y(unit="1") "Dry-solids reading"
    annotation (Placement(transformation(extent={{100,-10},{120,10}})));
equation
  port.m_flow = 0;
  y = port.x + bias + drift*time;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Ellipse(extent={{-80,80},{80,-80}}, lineColor={0,0,127}, fillColor={255,255,255}, fillPattern=FillPattern.Solid), Text(extent={{-60,40},{60,-40}}, textString="DS"), Text(extent={{-150,-105},{150,-135}}, textString="%name")}), Documentation(info="<html>
<p>Reads the dry-solids fraction of the stream at its port; the plant may add
a bias and a drift (0.5-1 %DS per month in the evaporator notes). Noise is
added in Python by the bench.</p>
</html>"));
end DrySolidsMeter;
