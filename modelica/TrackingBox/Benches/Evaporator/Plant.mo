within TrackingBox.Benches.Evaporator;
model Plant "Last-effect slice, plant: fouling, scaling, BPR offset, vent, heat loss, valve and pump wear, DS-meter drift"
  extends TrackingBox.Benches.Evaporator.BaseClasses.PartialSlice(
    effect(use_Rf_in=true, dBPR=dBPR, ventFraction=ventFraction, UA_loss=UA_lossEffect),
    flash(UA_loss=UA_lossFlash),
    inletValve(KvMax=15.5),
    outletValve(KvMax=7.6),
    pump(dp0=3.7e5, VMax=2.8e-3),
    DS_product(bias=DSbias, drift=DSdrift));
  parameter Real RfInf(unit="m2.K/W") = 2e-4 "Asymptote of the organic/CaCO3 fouling resistance";
  parameter TrackingBox.Units.Time tauFouling = 86400 "Time constant of the fouling growth";
  parameter Real Rf0(unit="m2.K/W") = 0 "Fouling resistance at time 0";
  parameter Real kScale(unit="m2.K/(W.s)") = 1e-9 "Growth rate of the soluble scale at full duty above the onset";
  parameter TrackingBox.Units.Fraction xScale = 0.5 "Dry-solids fraction at the onset of the soluble scale";
  parameter TrackingBox.Units.Fraction dxScale = 0.01 "Width of the scaling onset";
  parameter TrackingBox.Units.Time tauWash = 172800 "Time constant of the scale's removal by the liquor";
  parameter TrackingBox.Units.HeatFlowRate Q_nominal = 1.6e6 "Duty at which the scale grows at kScale";
  parameter TrackingBox.Units.TemperatureDifference dBPR = 1.0 "Boiling-point offset of the real liquor";
  parameter TrackingBox.Units.Fraction ventFraction = 0.01 "Steam vented from the chest (fraction of the condensate)";
  parameter TrackingBox.Units.ThermalConductance UA_lossEffect = 90 "Heat-loss conductance of the effect";
  parameter TrackingBox.Units.ThermalConductance UA_lossFlash = 30 "Heat-loss conductance of the flash tank";
  parameter TrackingBox.Units.Fraction DSbias = 0.002 "Bias of the DS meter";
  parameter Real DSdrift(unit="1/s") = 2.9e-9 "Drift of the DS meter (0.75 %DS per month)";
  Real Rf_scale(unit="m2.K/W", start=0, fixed=true) "Soluble-scale resistance";
  Real Rf_fouling(unit="m2.K/W") "Organic/CaCO3 fouling resistance";
  Real Rf_true(unit="m2.K/W") "Total fouling resistance of the plant (the truth the twin's Rf tracks)";
equation
  Rf_fouling = Rf0 + (RfInf - Rf0)*(1 - exp(-time/tauFouling));
  der(Rf_scale) = kScale/(1 + exp(-(effect.x - xScale)/dxScale))*effect.Q/Q_nominal - Rf_scale/tauWash;
  Rf_true = Rf_fouling + Rf_scale;
  effect.Rf_in = Rf_true;
  annotation (
    Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
      Text(extent={{-90,-62},{90,-92}}, textString="plant", textColor={0,0,0})}),
    experiment(StopTime=3600, Tolerance=1e-6), Documentation(info="<html>
<p>The degradations of the evaporator notes (section 5), with magnitudes as
parameters a bench can override: fouling growing asymptotically
<code>Rf0 + (RfInf - Rf0)(1 - exp(-t/tauFouling))</code>; soluble scale
growing above about 50 % DS in proportion to the duty and washed off with
<code>tauWash</code> (<code>dRs/dt = kScale&middot;&sigma;((x - xScale)/dxScale)&middot;Q/Q_nominal - Rs/tauWash</code>);
their sum <code>Rf_true</code> drives the effect's fouling input. A
boiling-point offset <code>dBPR</code>, a steam vent, heat losses, a worn
inlet valve (KvMax 15.5 instead of 17), an eroded outlet valve (7.6 instead
of 7), a worn pump (3.7 bar and 2.8 l/s instead of 4 bar and 3 l/s) and a
drifting DS meter. Sensor noise is added by the bench in Python.</p>
</html>"));
end Plant;
