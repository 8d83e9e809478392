within TrackingBox.Media.Water;
function cp "Specific heat capacity of liquid water"
  input TrackingBox.Units.Temperature T "Temperature";
  output TrackingBox.Units.SpecificHeatCapacity cp "Specific heat capacity at constant pressure";
protected
  Real t(unit="degC") "Celsius temperature, clipped to the validity range";
algorithm
  t := min(max(T - 273.15, 0), 150);
  cp := 4217.95 + t*(-2.41972 + t*(0.0470422 + t*(-3.27588e-4 + t*9.94273e-7)));
  annotation (Documentation(info="<html>
<p>Quartic polynomial in degC fitted to steam-table values 0..150 degC; the
argument is clipped to that range.</p>
</html>"));
end cp;
