within TrackingBox.Interfaces;
connector FluidPort_b "Outlet port (design flow out of the component); sets T"
  extends FluidPort;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Ellipse(extent={{-70,70},{70,-70}}, lineColor={0,127,255}, fillColor={255,255,255}, fillPattern=FillPattern.Solid)}),
    Documentation(info="<html>
<p>The outlet of a component (<code>port_b</code>), drawn as an open circle:
the design flow leaves here, <code>m_flow &lt; 0</code>. The component
<em>sets</em> the temperature <code>T</code> of the water it delivers (its
outlet temperature); every <code>port_a</code> connected to it reads that
value. One <code>port_b</code> may feed several <code>port_a</code> (a split);
two <code>port_b</code> must not be connected to each other.</p>
</html>"));
end FluidPort_b;
