within TrackingBox.Benches.Evaporator.Hidden;
model BurkeiteScale "Evaporator plant that scales with burkeite while its liquor is supersaturated (above 79.5 % DS)"
  extends Clean(effect(use_dRf_in=true));
  parameter TrackingBox.Units.Fraction xSat = 0.795 "Dry solids at which burkeite saturates";
  parameter Real kSat(unit="m2.K/(W.s)") = 2.0e-6 "Growth of the scale's resistance per unit supersaturation";
  parameter TrackingBox.Units.Time tauDissolve = 14400 "Time constant of the scale's dissolution below saturation";
  Real Rs(unit="m2.K/W", start=0, fixed=true) "Resistance of the burkeite scale";
equation
  der(Rs) = kSat*TrackingBox.Evaporation.Functions.splus(effect.x - xSat, 0.002) - TrackingBox.Evaporation.Functions.splus(xSat - effect.x, 0.002)/0.01*Rs/tauDissolve;
  effect.dRf_in = Rs;
  annotation (Documentation(info="<html>
<p>Growth in proportion to the supersaturation, <code>kSat&middot;s&#8314;(x -
xSat)</code> (2e-8 m2K/W per s at 1 %DS above saturation: 7e-5 in an hour), and
dissolution below saturation in proportion to the undersaturation (time constant
<code>tauDissolve</code> at 1 %DS below). It replaces the bench plant's scale
law (which <code>Clean</code> switches off) and adds to the fouling through the
effect's extra resistance: <code>Rf_true</code> (the truth of the twin's fouling)
stays the fouling alone.</p>
</html>"));
end BurkeiteScale;
