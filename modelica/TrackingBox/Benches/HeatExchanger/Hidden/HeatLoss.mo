within TrackingBox.Benches.HeatExchanger.Hidden;
model HeatLoss "Heat-exchanger plant whose hot side loses heat to the surroundings (natural convection)"
  extends TrackingBox.Benches.HeatExchanger.Plant(hx(use_heatLoss=true));
  parameter TrackingBox.Units.Temperature TSurr = 291.15 "Temperature of the surroundings";
  parameter Real c(unit="W/K") = 40 "Loss per kelvin of the hot inlet cell at 1 K (scales (T - TSurr)^1.25)";
  TrackingBox.Interfaces.RealOutput QLoss(unit="W") "Heat lost by the hot side"
    annotation (Placement(transformation(origin={0,110}, extent={{-10,-10},{10,10}}, rotation=90)));
equation
  QLoss = c*noEvent(max(hx.T1[1] - TSurr, 0))^1.25;
  connect(QLoss, hx.Q_flow_loss_in);
  annotation (Documentation(info="<html>
<p>Uninsulated hot header: <code>Q = c&middot;(T1[1] - TSurr)^1.25</code> (natural
convection, driven by the hottest cell), about 5.8 kW at 90 degC inlet, taken
evenly from the hot cells. Present from the start.</p>
</html>"));
end HeatLoss;
