within TrackingBox.Benches.Evaporator.Hidden;
model VentAndLoss "Evaporator plant with two effects: a steam-chest vent and an uninsulated effect shell"
  extends VentOrifice(effect(use_heatLoss=true));
  parameter Real c(unit="W/K") = 45 "Shell loss at 1 K above the hall (scales (T - THall)^1.25)";
  parameter TrackingBox.Units.Temperature THall = 298.15 "Temperature of the hall";
  TrackingBox.Interfaces.RealOutput Q_shell(unit="W") "Heat lost by the effect's shell"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  Q_shell = c*TrackingBox.Evaporation.Functions.splus(effect.T - THall, 0.1)^1.25;
  connect(Q_shell, effect.Q_flow_loss_in);
  annotation (Documentation(info="<html>
<p><code>VentOrifice</code> and the shell loss of <code>ShellLoss</code> at once
(two effects on the same unit).</p>
</html>"));
end VentAndLoss;
