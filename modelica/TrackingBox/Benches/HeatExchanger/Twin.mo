within TrackingBox.Benches.HeatExchanger;
model Twin "Heat-exchanger bench, digital twin (kht = 1000)"
  extends TrackingBox.Benches.HeatExchanger.BaseClasses.PartialBench;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Text(extent={{-90,-62},{90,-92}}, textString="twin", textColor={0,0,0})}),
    Documentation(info="<html>
<p>Digital twin with the design heat-transfer coefficient 1000 W/(m2.K).
Tracking parameter <code>hx.kht</code> (bounds 500..1500); an augmented model
sets <code>hx(use_kht_in=true)</code> and connects <code>hx.kht_in</code>.</p>
</html>"));
end Twin;
