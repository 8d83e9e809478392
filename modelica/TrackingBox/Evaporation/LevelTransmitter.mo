within TrackingBox.Evaporation;
block LevelTransmitter "dP level transmitter with a fixed calibration density"
  parameter TrackingBox.Units.Density rho_cal = 1450 "Calibration density";
  parameter TrackingBox.Units.PressureDifference dp0 = 0 "Zero offset of the transmitter (dP at zero level)";
  parameter TrackingBox.Units.Acceleration g = 9.81 "Gravity";
  parameter Boolean use_error_in = false "= true to add the input error_in to the reading (diagnosis hook)";
  TrackingBox.Interfaces.RealInput dp(unit="Pa") "Hydrostatic pressure difference between the taps"
    annotation (Placement(transformation(extent={{-140,-20},{-100,20}})));
  TrackingBox.Interfaces.RealOutput y(unit="m") "Level reading"
    annotation (Placement(transformation(extent={{100,-10},{120,10}})));
  TrackingBox.Interfaces.RealInput error_in(unit="m") if use_error_in "Error of the reading (diagnosis hook)"
    annotation (Placement(transformation(origin={0,-120}, extent={{-20,-20},{20,20}}, rotation=90)));
protected
  TrackingBox.Interfaces.RealInput error_internal(unit="m") "Error of the reading (0 without the hook)";
equation
  connect(error_in, error_internal);
  if not use_error_in then
    error_internal = 0;
  end if;
  y = (dp - dp0)/(rho_cal*g) + error_internal;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Ellipse(extent={{-80,80},{80,-80}}, lineColor={0,0,127}, fillColor={255,255,255}, fillPattern=FillPattern.Solid), Text(extent={{-60,40},{60,-40}}, textString="LT"), Text(extent={{-150,-105},{150,-135}}, textString="%name")}), Documentation(info="<html>
<p><code>L_m = (dP - dP0)/(&rho;_cal&middot;g)</code>: a liquor denser than
<code>rho_cal</code> reads high, a lighter one (or foam) reads low. Diagnosis hook (off by
default): <code>use_error_in</code> adds the input <code>error_in</code> (m) to the
reading.</p>
</html>"));
end LevelTransmitter;
