within TrackingBox.Media.Water;
function TSat "Saturation temperature of water"
  input TrackingBox.Units.Pressure p "Pressure";
  output TrackingBox.Units.Temperature T "Saturation temperature";
algorithm
  T := 3927.532/(23.36659 - log(max(p, 1))) + 41.48404;
  annotation (Documentation(info="<html>
<p>Inverse of <code>pSat</code>; valid 0.6..480 kPa.</p>
</html>"));
end TSat;
