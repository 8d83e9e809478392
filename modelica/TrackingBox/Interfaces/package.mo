within TrackingBox;
package Interfaces "Connectors and partial models"
  annotation (Documentation(info="<html>
<p>Signal connectors <code>RealInput</code>/<code>RealOutput</code> and the
fluid port. Fluid convention: see <code>FluidPort</code>.</p>
</html>"));
end Interfaces;
