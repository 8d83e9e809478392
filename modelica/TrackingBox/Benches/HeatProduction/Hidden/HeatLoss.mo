within TrackingBox.Benches.HeatProduction.Hidden;
model HeatLoss "Heat-production plant whose preheating tank T100 has lost its insulation"
  extends TrackingBox.Benches.HeatProduction.Plant(T100(use_heatLoss=true));
  parameter Real c(unit="W/K") = 8 "Loss per kelvin at 1 K (scales (T - TAmb)^1.25)";
  TrackingBox.Interfaces.RealOutput QLoss(unit="W") "Extra heat lost by T100"
    annotation (Placement(transformation(origin={0,110}, extent={{-10,-10},{10,10}}, rotation=90)));
equation
  QLoss = c*noEvent(max(T100.T - TAmb, 0))^1.25;
  connect(QLoss, T100.Q_flow_loss_in);
  annotation (Documentation(info="<html>
<p>Natural convection from the bare wall of T100 to the measured ambient:
<code>c&middot;(T - TAmb)^1.25</code>, about 690 W at 55 degC and 20 degC
ambient, on top of the designed <code>UA&middot;(T - TAmb)</code>. Present from
the start: TIC100 makes up for it with the preheater.</p>
</html>"));
end HeatLoss;
