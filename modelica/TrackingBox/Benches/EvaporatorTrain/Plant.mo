within TrackingBox.Benches.EvaporatorTrain;
model Plant "N-effect evaporator train, plant: fouling and scaling per effect, BPR offsets, vents, heat losses, wear, DS-meter drift"
  extends TrackingBox.Benches.EvaporatorTrain.BaseClasses.PartialTrain(
    useRfInput=true,
    effect(dBPR={0.5 + 0.5*(N - k)/(N - 1) for k in 1:N}),
    ventFractionAll=0.005,
    UA_lossAll=200,
    UA_lossFlash=30,
    inletValve(capacity=0.9),
    transferPump(each head=0.95),
    DSbias=0.002,
    DSdrift=2.9e-9);
  parameter Real RfInf[N](each unit="m2.K/W") = {1.5e-4 - 1.0e-4*(k - 1)/(N - 1) for k in 1:N} "Asymptote of each effect's organic/CaCO3 fouling (highest at the product end)";
  parameter TrackingBox.Units.Time tauFouling[N] = {86400*(1 + 0.5*(k - 1)/(N - 1)) for k in 1:N} "Time constant of each effect's fouling growth";
  parameter Real Rf0(unit="m2.K/W") = 0 "Fouling resistance of every effect at time 0";
  parameter Real kScale(unit="m2.K/(W.s)") = 1e-9 "Growth rate of the soluble scale at design duty above the onset";
  parameter TrackingBox.Units.Fraction xScale = 0.5 "Dry-solids fraction at the onset of the soluble scale";
  parameter TrackingBox.Units.Fraction dxScale = 0.01 "Width of the scaling onset";
  parameter TrackingBox.Units.Time tauWash = 172800 "Time constant of the scale's removal by the liquor";
  Real Rf_scale[N](each unit="m2.K/W", each start=0, each fixed=true) "Soluble-scale resistance of each effect";
  Real Rf_fouling[N](each unit="m2.K/W") "Organic/CaCO3 fouling resistance of each effect";
  Real Rf_true[N](each unit="m2.K/W") "Total fouling resistance of each effect (the truth the twin's effect[k].Rf tracks)";
equation
  // (der(...)) in parentheses: rumoca 0.10.2 loses the right-hand side of der(...) = ... in
  // for-loops, and the shipped library is not rewritten when a wrapper model uses it (--effects N)
  for k in 1:N loop
    Rf_fouling[k] = Rf0 + (RfInf[k] - Rf0)*(1 - exp(-time/tauFouling[k]));
    (der(Rf_scale[k])) = kScale/(1 + exp(-(effect[k].x - xScale)/dxScale))*effect[k].Q/QDesign[k] - Rf_scale[k]/tauWash;
    Rf_true[k] = Rf_fouling[k] + Rf_scale[k];
    effect[k].Rf_in = Rf_true[k];
  end for;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Text(extent={{-90,-62},{90,-92}}, textString="plant", textColor={0,0,0})}),
    experiment(StopTime=3600, Tolerance=1e-6), Documentation(info="<html>
<p>The degradations of the evaporator notes (section 5) in every effect:
fouling growing asymptotically to <code>RfInf[k]</code> (1.5e-4 m2K/W at the
product end down to 0.5e-4 at the feed end, 8-10 % of U) with its own time constant; soluble
scale above about 50 % DS (in practice effects 1 and 2) growing with the duty
and washed off with <code>tauWash</code>; their sum <code>Rf_true[k]</code>
drives effect <code>k</code>'s fouling input. Boiling-point offsets from 1 K
(effect 1) to 0.5 K (effect N), 0.5 % steam vents, heat losses, a worn feed
valve (90 % of its capacity), worn transfer pumps (95 % of their head) and a
drifting product DS meter. Sensor noise is added by the bench in Python.</p>
</html>"));
end Plant;
