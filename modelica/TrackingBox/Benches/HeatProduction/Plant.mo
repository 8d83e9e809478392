within TrackingBox.Benches.HeatProduction;
model Plant "Heat-production process, plant: quadratic curves and degraded components"
  extends TrackingBox.Benches.HeatProduction.BaseClasses.PartialProcess(
    quadratic=true,
    HU300(kht=1000),
    HEX300(kht=920),
    Pipe100(k=0.0065),
    Pipe101(k=0.004),
    Pipe200(k=0.006),
    Pipe201(k=0.0045),
    V100(KvMax=0.96),
    V200(KvMax=1.03),
    V300(KvMax=0.95),
    V400(KvMax=1.04),
    PU100(VFlowDesign=6.3e-5, uRise=37500),
    PU200(VFlowDesign=8.1e-5, uRise=38500));
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Text(extent={{-90,-62},{90,-92}}, textString="plant", textColor={0,0,0})}),
    Documentation(info="<html>
<p>Stands in for the physical process: quadratic pipe and pump curves and
degraded or off-design components, all within the tracking bounds: HU300
fouled (kht 1000 instead of 1050), HEX300 fouled (kht 920, 8 % low), worn
PU100 (6.3e-5 m3/s, 37.5 kPa) and PU200 (8.1e-5 m3/s, 38.5 kPa), pipe
coefficients and valve capacities off their design values.</p>
</html>"));
end Plant;
