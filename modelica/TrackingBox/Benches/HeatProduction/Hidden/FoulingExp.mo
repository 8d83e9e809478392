within TrackingBox.Benches.HeatProduction.Hidden;
model FoulingExp "Heat-production plant whose heat exchanger HEX300 fouls exponentially"
  extends TrackingBox.Benches.HeatProduction.Plant(HEX300(use_kht_in=true));
  parameter TrackingBox.Units.Time tStart = 14400 "Start of the fouling";
  parameter TrackingBox.Units.Time tau = 36000 "Time constant of the deposit build-up";
  parameter TrackingBox.Units.Fraction fall = 0.35 "Final relative fall of kht";
  TrackingBox.Interfaces.RealOutput khtFouled(unit="W/(m2.K)") "Heat-transfer coefficient of the fouled HEX300"
    annotation (Placement(transformation(origin={0,110}, extent={{-10,-10},{10,10}}, rotation=90)));
equation
  khtFouled = HEX300.kht*(1 - fall*(1 - exp(-noEvent(max(time - tStart, 0))/tau)));
  connect(khtFouled, HEX300.kht_in);
  annotation (Documentation(info="<html>
<p>From <code>tStart</code> on, <code>kht = kht0&middot;(1 - fall&middot;(1 -
exp(-(t - tStart)/tau)))</code>: 32 % lower at the end of a 24-hour case.</p>
</html>"));
end FoulingExp;
