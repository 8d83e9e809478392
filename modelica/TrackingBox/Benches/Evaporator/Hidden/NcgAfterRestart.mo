within TrackingBox.Benches.Evaporator.Hidden;
model NcgAfterRestart "Evaporator plant whose steam chest fills with air in every stoppage: after a restart it is blanketed until vented"
  extends Clean(effect(use_dRf_in=true));
  parameter Real RBlanket(unit="m2.K/W") = 2.5e-4 "Resistance of a chest full of air";
  parameter TrackingBox.Units.Time tauFill = 600 "Time constant of the air filling the chest while the steam is off";
  parameter TrackingBox.Units.Time tauVent = 2400 "Time constant of venting the air after the restart";
  parameter TrackingBox.Units.MassFlowRate feedStopped = 0.5 "Feed below which the effect counts as stopped";
  Real Rncg(unit="m2.K/W", start=0, fixed=true) "Resistance of the air blanket on the condensing side";
  Real stopped(unit="1") "1 in a stoppage, 0 running (smooth)";
equation
  stopped = 1/(1 + exp((inletValve.m_flow - feedStopped)/0.05));
  der(Rncg) = stopped*(RBlanket - Rncg)/tauFill - (1 - stopped)*Rncg/tauVent;
  effect.dRf_in = Rncg;
  annotation (Documentation(info="<html>
<p>Non-condensable gases blanket the condensing side after every restart and are
vented with a time constant of 40 min (evaporator notes, section 5: NCG
blanketing, at least 21 % heat-transfer loss [S27]). Outside the effect library
(no entry describes an air blanket that comes and goes with the stoppages): the
suite expects no name, and the residual reported where it shows, after the
restarts.</p>
</html>"));
end NcgAfterRestart;
