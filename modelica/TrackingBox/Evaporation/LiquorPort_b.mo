within TrackingBox.Evaporation;
connector LiquorPort_b "Liquor outlet port (design flow out of the component); sets x and T"
  extends TrackingBox.Evaporation.LiquorPort;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Ellipse(extent={{-70,70},{70,-70}}, lineColor={139,90,43}, fillColor={255,255,255}, fillPattern=FillPattern.Solid)}),
    Documentation(info="<html>
<p>The liquid outlet of an evaporation component (<code>port_b</code>), drawn as
an open brown circle: the design flow leaves here (<code>m_flow &lt; 0</code>),
and the component sets <code>x</code> and <code>T</code> of the liquid it
delivers (a vessel: its own well-mixed <code>x</code> and <code>T</code>; a
valve or pump: those of its inlet).</p>
</html>"));
end LiquorPort_b;
