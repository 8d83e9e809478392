within TrackingBox.Benches.EvaporatorTrain.Hidden;
model ShellLoss "Train plant whose effect-2 shell is uninsulated (natural convection to the hall)"
  extends Clean(effect(each use_heatLoss=true));
  parameter Integer kLoss(min=1) = 2 "The effect whose shell loses heat";
  parameter TrackingBox.Units.Temperature THall = 298.15 "Temperature of the hall";
  parameter Real lossShare = 0.01 "Loss at the effect's design liquor temperature, as a fraction of its design duty";
  parameter Real c(unit="W/K") = lossShare*QDesign[kLoss]/(TLiqDesign[kLoss] - THall)^1.25 "Loss at 1 K above the hall (scales (T - THall)^1.25)";
  TrackingBox.Interfaces.RealOutput Q_shell[N](each unit="W") "Heat lost by each effect's shell (0 but for effect kLoss)"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
equation
  for k in 1:N loop
    Q_shell[k] = if k == kLoss then c*TrackingBox.Evaporation.Functions.splus(effect[k].T - THall, 0.1)^1.25 else 0;
    connect(Q_shell[k], effect[k].Q_flow_loss_in);
  end for;
  annotation (Documentation(info="<html>
<p><code>Q = c&middot;(T - THall)^1.25</code> on the shell of effect
<code>kLoss</code> (2), sized to 1 % of that effect's design duty at its design
liquor temperature (3-effect train at the nominal inputs: 142 kW at 85 degC, 1.2 %
of the duty there). The other shells are insulated.</p>
</html>"));
end ShellLoss;
