within TrackingBox.Evaporation;
model DrySolidsMeter "Dry-solids meter on a liquor line, with bias and drift"
  parameter TrackingBox.Units.Fraction bias = 0 "Constant bias";
  parameter Real drift(unit="1/s") = 0 "Drift rate of the bias (plant)";
  TrackingBox.Evaporation.LiquorPort_a port "Measuring point (no flow)";
  TrackingBox.Interfaces.RealOutput y(unit="1") "Dry-solids reading";
equation
  port.m_flow = 0;
  y = port.x + bias + drift*time;
  annotation (Documentation(info="<html>
<p>Reads the dry-solids fraction of the stream at its port; the plant may add
a bias and a drift (0.5-1 %DS per month in the evaporator notes). Noise is
added in Python by the bench.</p>
</html>"));
end DrySolidsMeter;
