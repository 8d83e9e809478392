within TrackingBox;
package Blocks "Control blocks"
  annotation (Documentation(info="<html>
<p>Controller blocks for the process models. Boolean signals are not used:
logical inputs are Real signals, true when greater than 0.5.</p>
</html>"));
end Blocks;
