within TrackingBox.Media.Water;
function pSat "Saturation pressure of water"
  input TrackingBox.Units.Temperature T "Temperature";
  output TrackingBox.Units.Pressure p "Saturation pressure";
algorithm
  p := exp(23.36659 - 3927.532/(T - 41.48404));
  annotation (Documentation(info="<html>
<p>Antoine form <code>ln(p/Pa) = A - B/(T/K + C)</code> fitted to steam tables
0..150 degC (within 0.3 %).</p>
</html>"));
end pSat;
