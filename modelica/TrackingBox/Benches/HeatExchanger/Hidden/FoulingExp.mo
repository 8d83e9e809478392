within TrackingBox.Benches.HeatExchanger.Hidden;
model FoulingExp "Heat-exchanger plant whose heat-transfer coefficient falls exponentially (fouling)"
  extends TrackingBox.Benches.HeatExchanger.Plant(hx(use_kht_in=true));
  parameter TrackingBox.Units.Time tStart = 3600 "Start of the fouling";
  parameter TrackingBox.Units.Time tau = 14400 "Time constant of the deposit build-up";
  parameter TrackingBox.Units.Fraction fall = 0.25 "Final relative fall of kht";
  TrackingBox.Interfaces.RealOutput khtFouled(unit="W/(m2.K)") "Heat-transfer coefficient of the fouled exchanger"
    annotation (Placement(transformation(origin={0,110}, extent={{-10,-10},{10,10}}, rotation=90)));
equation
  khtFouled = hx.kht*(1 - fall*(1 - exp(-noEvent(max(time - tStart, 0))/tau)));
  connect(khtFouled, hx.kht_in);
  annotation (Documentation(info="<html>
<p>From <code>tStart</code> on, <code>kht = kht0&middot;(1 - fall&middot;(1 -
exp(-(t - tStart)/tau)))</code>: a deposit that builds up quickly and levels off
(25 % in the limit, 16 % after two hours, 22 % at the end of an 8-hour case).</p>
</html>"));
end FoulingExp;
