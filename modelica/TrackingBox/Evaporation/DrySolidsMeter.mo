within TrackingBox.Evaporation;
model DrySolidsMeter "Dry-solids meter on a liquor line, with bias and drift"
  parameter TrackingBox.Units.Fraction bias = 0 "Constant bias";
  parameter TrackingBox.Units.FractionRate drift = 0 "Drift rate of the bias (plant)";
  parameter Boolean use_error_in = false "= true to add the input error_in to the reading (diagnosis hook)";
  TrackingBox.Evaporation.LiquorPort_a port "Measuring point (no flow)"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  TrackingBox.Interfaces.RealOutput y(unit="1") "Dry-solids reading"
    annotation (Placement(transformation(extent={{100,-10},{120,10}})));
  TrackingBox.Interfaces.RealInput error_in(unit="1") if use_error_in "Error of the reading (diagnosis hook)"
    annotation (Placement(transformation(origin={0,-120}, extent={{-20,-20},{20,20}}, rotation=90)));
protected
  TrackingBox.Interfaces.RealInput error_internal(unit="1") "Error of the reading (0 without the hook)";
equation
  connect(error_in, error_internal);
  if not use_error_in then
    error_internal = 0;
  end if;
  port.m_flow = 0;
  y = port.x + bias + drift*time + error_internal;
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Ellipse(extent={{-80,80},{80,-80}}, lineColor={0,0,127}, fillColor={255,255,255}, fillPattern=FillPattern.Solid), Text(extent={{-60,40},{60,-40}}, textString="DS"), Text(extent={{-150,-105},{150,-135}}, textString="%name")}), Documentation(info="<html>
<p>Reads the dry-solids fraction of the stream at its port; the plant may add
a bias and a drift (0.5-1 %DS per month in the evaporator notes). Noise is
added in Python by the bench. Diagnosis hook (off by default):
<code>use_error_in</code> adds the input <code>error_in</code> to the reading.</p>
</html>"));
end DrySolidsMeter;
