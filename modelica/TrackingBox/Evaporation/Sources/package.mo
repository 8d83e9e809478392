within TrackingBox.Evaporation;
package Sources "Liquor pressure boundaries"
  annotation (Documentation(info="<html>
<p>Pressure boundaries for liquor and condensate lines:
<code>LiquorSource</code> sets the pressure, temperature and dry-solids
fraction of the liquid it delivers through its <code>port</code>
(a <code>LiquorPort_b</code>); <code>LiquorSink</code> sets only the
pressure and takes <code>x</code> and <code>T</code> from upstream. Each
value can come from an input (<code>use_p_in</code>, <code>use_T_in</code>,
<code>use_x_in</code>). The flow through a boundary is whatever the network
of valves and pumps gives.</p>
</html>"));
end Sources;
