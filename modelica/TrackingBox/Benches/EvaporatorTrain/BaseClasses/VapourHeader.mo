within TrackingBox.Benches.EvaporatorTrain.BaseClasses;
model VapourHeader "Vapour header between two effects: a volume of saturated vapour collecting several vapour lines"
  import TrackingBox.Media.Water.Saturation;
  constant Real R_w(unit="J/(kg.K)") = 461.5 "Specific gas constant of water vapour";
  parameter Integer nPorts(min=1) = 3 "Number of inlets";
  parameter TrackingBox.Units.Volume V = 30 "Volume of the header and the vapour lines";
  parameter TrackingBox.Units.Temperature T_ref = 373.15 "Temperature in the ideal-gas law (fixed: it sets the capacity only)";
  parameter TrackingBox.Units.Pressure p_start = 1e5 "Initial pressure";
  TrackingBox.Interfaces.FluidPort_a port_a[nPorts] "Vapour inlets"
    annotation (Placement(transformation(extent={{-110,-10},{-90,10}})));
  TrackingBox.Interfaces.FluidPort_b port_b "Vapour outlet (to the next steam chest or the condenser)"
    annotation (Placement(transformation(extent={{90,-10},{110,10}})));
  TrackingBox.Units.Mass M(start=p_start*V/(R_w*T_ref), fixed=true) "Vapour mass";
  TrackingBox.Units.Pressure p "Pressure";
equation
  p = M*R_w*T_ref/V;
  der(M) = sum(port_a[i].m_flow for i in 1:nPorts) + port_b.m_flow;
  for i in 1:nPorts loop
    port_a[i].p = p;
  end for;
  port_b.p = p;
  port_b.T = Saturation.TSat(p);
  annotation (Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={Rectangle(extent={{-100,40},{100,-40}}, lineColor={0,0,0}, fillColor={230,230,255}, fillPattern=FillPattern.Solid), Text(extent={{-150,-45},{150,-75}}, textString="%name")}), Documentation(info="<html>
<p>One state, the vapour mass <code>M</code>; the pressure follows the ideal-gas
law at the fixed temperature <code>T_ref</code> (which sets how fast the
pressure moves, not the balance). Every inlet sees the header pressure; the
outlet delivers saturated vapour. The header decouples the vapour lines that
meet in it (the effect's own vapour, the condensate flash, a flash tank's
vapour), so no algebraic loop forms between their square-root laws.</p>
</html>"));
end VapourHeader;
