within TrackingBox.Benches.HeatExchanger;
model Plant "Heat-exchanger bench, plant: fouled exchanger (kht = 910)"
  extends TrackingBox.Benches.HeatExchanger.BaseClasses.PartialBench(hx(kht=910));
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Text(extent={{-90,-62},{90,-92}}, textString="plant", textColor={0,0,0})}),
    Documentation(info="<html>
<p>Stands in for the physical exchanger: heat-transfer coefficient 910
W/(m2.K), 9 % below the twin's design value.</p>
</html>"));
end Plant;
