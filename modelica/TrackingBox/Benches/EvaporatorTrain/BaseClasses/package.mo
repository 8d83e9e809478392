within TrackingBox.Benches.EvaporatorTrain;
package BaseClasses "The train common to plant and twin, and its small junction components"
  annotation (Documentation(info="<html>
<p><code>PartialTrain</code> is the <code>N</code>-effect backward-feed train
(design point, effects, vapour headers, product flash tank, condensate
cascade, controllers, instruments) that plant and twin extend. The small
components it needs between effects: <code>VapourHeader</code> (a vapour
volume where several vapour lines meet), <code>VapourLine</code> (square-root
law), <code>VapourPlug</code> (a closed header inlet) and
<code>CondensateMixer</code> (adiabatic junction of two condensate
streams).</p>
</html>"));
end BaseClasses;
