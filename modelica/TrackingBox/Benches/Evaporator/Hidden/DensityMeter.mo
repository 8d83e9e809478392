within TrackingBox.Benches.Evaporator.Hidden;
model DensityMeter "Evaporator plant whose product DS meter infers DS from density with the wrong liquor constant"
  extends Clean(DS_product(use_error_in=true));
  parameter Real kTrue(unit="kg/m3") = 694 "Density constant of the real liquor (rho = (997 + k x) f(T))";
  parameter Real kMeter(unit="kg/m3") = 649 "Density constant the meter's calibration assumes";
  TrackingBox.Interfaces.RealOutput DS_error(unit="1") "Error of the DS reading"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  // the meter measures rho = (997 + kTrue x) f(T) and inverts it with kMeter: x_read = x kTrue/kMeter
  DS_error = DS_product.port.x*(kTrue/kMeter - 1);
  connect(DS_error, DS_product.error_in);
  annotation (Documentation(info="<html>
<p>Evaporator notes, section 1: the density correlation's constant is 649 in
one source and 694 in another; a meter calibrated with 649 on a liquor of 694
reads <code>x&middot;694/649</code>, 5.3 %DS high at 77 %.</p>
</html>"));
end DensityMeter;
