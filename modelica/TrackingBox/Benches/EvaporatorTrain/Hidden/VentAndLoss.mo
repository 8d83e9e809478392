within TrackingBox.Benches.EvaporatorTrain.Hidden;
model VentAndLoss "Train plant with two hidden effects: the vent of VentOrifice on effect 1 and the shell loss of ShellLoss on effect 2"
  extends VentOrifice(effect(each use_heatLoss=true));
  parameter Integer kLoss(min=1) = 2 "The effect whose shell loses heat";
  parameter TrackingBox.Units.Temperature THall = 298.15 "Temperature of the hall";
  parameter Real lossShare = 0.01 "Loss at the effect's design liquor temperature, as a fraction of its design duty";
  parameter Real c(unit="W/K") = lossShare*QDesign[kLoss]/(TLiqDesign[kLoss] - THall)^1.25 "Loss at 1 K above the hall (scales (T - THall)^1.25)";
  TrackingBox.Interfaces.RealOutput Q_shell[N](each unit="W") "Heat lost by each effect's shell (0 but for effect kLoss)"
    annotation (Placement(transformation(extent={{100,20},{120,40}})));
equation
  for k in 1:N loop
    Q_shell[k] = if k == kLoss then c*TrackingBox.Evaporation.Functions.splus(effect[k].T - THall, 0.1)^1.25 else 0;
    connect(Q_shell[k], effect[k].Q_flow_loss_in);
  end for;
  annotation (Documentation(info="<html>
<p>The two-effect case on different units: effect 1's chest vents through the
orifice of <code>VentOrifice</code>, effect 2's shell loses heat as in
<code>ShellLoss</code>.</p>
</html>"));
end VentAndLoss;
