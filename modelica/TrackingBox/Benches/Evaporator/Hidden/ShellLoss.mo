within TrackingBox.Benches.Evaporator.Hidden;
model ShellLoss "Evaporator plant whose effect shell is uninsulated (natural convection to the hall)"
  extends Clean(effect(use_heatLoss=true));
  parameter Real c(unit="W/K") = 45 "Loss at 1 K above the hall (scales (T - THall)^1.25)";
  parameter TrackingBox.Units.Temperature THall = 298.15 "Temperature of the hall";
  TrackingBox.Interfaces.RealOutput Q_shell(unit="W") "Heat lost by the effect's shell"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  Q_shell = c*TrackingBox.Evaporation.Functions.splus(effect.T - THall, 0.1)^1.25;
  connect(Q_shell, effect.Q_flow_loss_in);
  annotation (Documentation(info="<html>
<p><code>Q = c&middot;(T - THall)^1.25</code>: about 15 kW at 131 degC, 0.9 % of
the duty.</p>
</html>"));
end ShellLoss;
