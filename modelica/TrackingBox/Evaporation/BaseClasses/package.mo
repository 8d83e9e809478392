within TrackingBox.Evaporation;
package BaseClasses "Partial models of the evaporation components"
  annotation (Documentation(info="<html>
<p><code>PartialVessel</code>: the well-mixed liquor volume with its vapour
space that <code>Effect</code>, <code>FlashTank</code> and
<code>CondensateTank</code> extend. It holds the states (liquid mass, dry-solids
mass, temperature, vapour mass), the exact energy balance of the inventory
<code>M&middot;h(x, T)</code>, the smooth boiling law and the vapour line; an
extending model adds only the heat <code>Q</code> it brings to the liquid.</p>
</html>"));
end BaseClasses;
