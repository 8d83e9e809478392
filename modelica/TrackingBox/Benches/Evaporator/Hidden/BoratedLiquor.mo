within TrackingBox.Benches.Evaporator.Hidden;
model BoratedLiquor "Evaporator plant whose liquor carries borate: it boils 2 K hotter above about 72 % dry solids"
  extends Clean(effect(use_dBPR_in=true), flash(use_dBPR_in=true));
  parameter TrackingBox.Units.TemperatureDifference dTBorate = 2 "Extra boiling-point rise at high dry solids";
  parameter TrackingBox.Units.Fraction xBorate = 0.72 "Dry solids at the middle of the borate's onset";
  TrackingBox.Interfaces.RealOutput dBPR_effect(unit="K") "Boiling-point offset of the effect's liquor"
    annotation (Placement(transformation(extent={{100,50},{120,70}})));
  TrackingBox.Interfaces.RealOutput dBPR_flash(unit="K") "Boiling-point offset of the flash tank's liquor"
    annotation (Placement(transformation(extent={{100,10},{120,30}})));
equation
  dBPR_effect = dBPR + dTBorate/(1 + exp(-(effect.x - xBorate)/0.02));
  dBPR_flash = dTBorate/(1 + exp(-(flash.x - xBorate)/0.02));
  connect(dBPR_effect, effect.dBPR_in);
  connect(dBPR_flash, flash.dBPR_in);
  annotation (Documentation(info="<html>
<p>Borate raises the boiling point at high dry solids (evaporator notes, section
1: about 5 K above 70 % DS [S6]); here <code>dTBorate&middot;&sigma;((x -
0.72)/0.02)</code>, 1.5-2 K over the slice's 74-81 % DS, in the effect (on top
of its 1 K offset) and in the flash tank.</p>
</html>"));
end BoratedLiquor;
