within TrackingBox.Benches.Evaporator.Hidden;
model FoamingFlash "Evaporator plant whose flash-tank level transmitter is calibrated for a liquor 8 % denser than it"
  extends Clean(LT_flash(use_error_in=true));
  parameter TrackingBox.Units.Density rhoCal = 1570 "Density the transmitter was calibrated for (the design's 1450 intended)";
  TrackingBox.Interfaces.RealOutput LT_error(unit="m") "Error of the flash-tank level reading"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  LT_error = (LT_flash.dp - LT_flash.dp0)/LT_flash.g*(1/rhoCal - 1/LT_flash.rho_cal);
  connect(LT_error, LT_flash.error_in);
  annotation (Documentation(info="<html>
<p>The reading is <code>dp/(rhoCal&middot;g)</code> with rhoCal 1570 kg/m3
where 1450 was meant: 8 % low, so the flash level loop holds the true level 8 cm
higher than the twin does, and the pump sees that much more head.</p>
</html>"));
end FoamingFlash;
