within TrackingBox.Media;
package Water "Liquid water, 0..150 degC, and water/steam saturation properties"
  annotation (Documentation(info="<html>
<p>Correlations for liquid water between 273.15 K and 423.15 K (0..150 degC),
fitted to steam-table values: <code>cp</code> (within 3 J/(kg.K)),
<code>rho</code> (within 0.2 %), saturation pressure <code>pSat</code> and its
inverse <code>TSat</code> (within 0.3 %). Pressure effects on the liquid are
neglected. For an evaporator, a solution medium can reuse <code>TSat</code>
and add a boiling-point-rise function of the dry-solids fraction (see
<code>Media.BlackLiquor</code>). The subpackage <code>Saturation</code> holds
the saturation line of water and steam from IAPWS-IF97, 20..200 degC.</p>
</html>"));
end Water;
