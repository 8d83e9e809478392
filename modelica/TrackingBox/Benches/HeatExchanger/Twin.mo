within TrackingBox.Benches.HeatExchanger;
model Twin "Heat-exchanger bench, digital twin (kht = 1000)"
  extends TrackingBox.Benches.HeatExchanger.BaseClasses.PartialBench;
  annotation (Documentation(info="<html>
<p>Digital twin with the design heat-transfer coefficient 1000 W/(m2.K).
Tracking parameter <code>hx.kht</code> (bounds 500..1500); an augmented model
sets <code>hx(use_kht_in=true)</code> and connects <code>hx.kht_in</code>.</p>
</html>"));
end Twin;
