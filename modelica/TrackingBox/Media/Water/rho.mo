within TrackingBox.Media.Water;
function rho "Density of liquid water"
  input TrackingBox.Units.Temperature T "Temperature";
  output TrackingBox.Units.Density rho "Density";
protected
  Real t(unit="degC") "Celsius temperature, clipped to the validity range";
algorithm
  t := min(max(T - 273.15, 0), 150);
  rho := 1000*(1 - (t + 288.9414)/(508929.2*(t + 68.12963))*(t - 3.9863)^2);
  annotation (Documentation(info="<html>
<p>Thiesen-type rational correlation (density maximum near 4 degC), within
0.2 % of steam tables up to 150 degC; the argument is clipped to 0..150 degC.</p>
</html>"));
end rho;
