within TrackingBox.Interfaces;
connector RealInput = input Real "Connector with one input signal of type Real"
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Polygon(points={{-100,100},{100,0},{-100,-100},{-100,100}}, lineColor={0,0,127}, fillColor={0,0,127},
        fillPattern=FillPattern.Solid)}),
    Documentation(info="<html>
<p>A Real input signal, drawn as a filled triangle pointing into the block.
Where a parameter can be switched to an input (the conditional-input pattern
<code>use_X_in</code>/<code>X_in</code>), the input is of this type; each
component also keeps a <em>protected</em> <code>X_internal</code> of this type,
connected to <code>X_in</code> when the input is used and bound to the
parameter <code>X</code> when it is not, so its equations read
<code>X_internal</code> only. Attributes such as <code>unit</code> are given
on the instance (<code>RealInput kht_in(unit=\"W/(m2.K)\")</code>).</p>
</html>"));
