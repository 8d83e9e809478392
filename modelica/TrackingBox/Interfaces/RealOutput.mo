within TrackingBox.Interfaces;
connector RealOutput = output Real "Connector with one output signal of type Real"
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Polygon(points={{-100,100},{100,0},{-100,-100},{-100,100}}, lineColor={0,0,127}, fillColor={255,255,255},
        fillPattern=FillPattern.Solid)}),
    Documentation(info="<html>
<p>A Real output signal, drawn as an open triangle pointing out of the block.
The benches' measurements are outputs of this type at the top level of the
plant and twin models (<code>TI_100</code>, <code>ThOut</code>, ...), so that
they become outputs of the FMU; a tracking box reads the twin's outputs and
compares them with the plant's measured tags.</p>
</html>"));
