within TrackingBox.Evaporation.Validation;
model SliceBalance "Mass, dry-solids and energy balances of the evaporator slice under varying boundaries and correction flows"
  extends TrackingBox.Icons.Example;
  import TrackingBox.Media.BlackLiquor;
  TrackingBox.Benches.Evaporator.Twin slice "The slice (twin variant: it has the correction-flow inputs)";
  TrackingBox.Units.Mass massIn(start=0, fixed=true) "Integral of the mass entering: feed, steam, correction flows";
  TrackingBox.Units.Mass massOut(start=0, fixed=true) "Integral of the mass leaving: product, condensate, vapour lines, steam vent";
  TrackingBox.Units.Mass solidsIn(start=0, fixed=true) "Integral of the dry solids entering: feed, correction flows";
  TrackingBox.Units.Mass solidsOut(start=0, fixed=true) "Integral of the dry solids leaving with the product";
  Real energyIn(unit="J", start=0, fixed=true) "Integral of the energy entering the liquid inventories: feed, heat from the steam, condensate into the tank, correction flows";
  Real energyOut(unit="J", start=0, fixed=true) "Integral of the energy leaving the liquid inventories: vapour from the liquids, product, condensate, heat losses";
  TrackingBox.Units.Mass massInventory "Liquid and vapour masses of all vessels and of the steam chest";
  TrackingBox.Units.Mass solidsInventory "Dry-solids masses of all vessels";
  Real energyInventory(unit="J") "Enthalpy of the liquid inventories, M*h(x, T)";
equation
  slice.feedFlowSet = 2 - 0.8*(0.5 + 0.5*tanh((time - 1800)/120));
  slice.feedDS = 0.52 + 0.02*sin(time/900);
  slice.feedT = 368.15 + 3*sin(time/700);
  slice.steamP = 4e5 + 2e4*sin(time/1200);
  slice.nextP = 1.4e5 - 3e3*sin(time/1500);
  slice.holdControllers = 0;
  slice.holdFlowController = 0;
  slice.holdLevelControllers = 0;
  slice.holdBodyLevelController = 0;
  slice.holdFlashLevelController = 0;
  slice.holdCondensateLevelController = 0;
  slice.body_m_flow_corr = 0.02*sin(time/600);
  slice.flash_m_flow_corr = 0.01*cos(time/500);
  slice.cond_m_flow_corr = 0.005*sin(time/400);
  der(massIn) = slice.inletValve.m_flow + slice.effect.m_steam + slice.effect.m_corr + slice.flash.m_corr + slice.condTank.m_corr;
  der(massOut) = slice.productValve.m_flow + slice.condValve.m_flow + slice.effect.m_vap_out + slice.flash.m_vap_out + slice.condTank.m_vap_out + slice.effect.m_vent;
  der(solidsIn) = slice.inletValve.port_a.x*slice.inletValve.m_flow + slice.effect.x*slice.effect.m_corr + slice.flash.x*slice.flash.m_corr + slice.condTank.x*slice.condTank.m_corr;
  der(solidsOut) = slice.productValve.port_a.x*slice.productValve.m_flow + slice.condValve.port_a.x*slice.condValve.m_flow;
  der(energyIn) = slice.inletValve.m_flow*BlackLiquor.specificEnthalpy(slice.inletValve.port_a.x, slice.inletValve.port_a.T) + slice.effect.Q + slice.condTank.m_in*slice.condTank.h_in + slice.effect.m_corr*slice.effect.h + slice.flash.m_corr*slice.flash.h + slice.condTank.m_corr*slice.condTank.h;
  der(energyOut) = slice.effect.m_ev*slice.effect.h_vap + slice.flash.m_ev*slice.flash.h_vap + slice.condTank.m_ev*slice.condTank.h_vap + slice.productValve.m_flow*BlackLiquor.specificEnthalpy(slice.productValve.port_a.x, slice.productValve.port_a.T) + slice.condValve.m_flow*BlackLiquor.specificEnthalpy(slice.condValve.port_a.x, slice.condValve.port_a.T) + slice.effect.Q_loss + slice.flash.Q_loss + slice.condTank.Q_loss;
  massInventory = slice.effect.M + slice.effect.M_vap + slice.effect.M_steam + slice.flash.M + slice.flash.M_vap + slice.condTank.M + slice.condTank.M_vap;
  solidsInventory = slice.effect.M_s + slice.flash.M_s + slice.condTank.M_s;
  energyInventory = slice.effect.M*slice.effect.h + slice.flash.M*slice.flash.h + slice.condTank.M*slice.condTank.h;
  annotation (experiment(StopTime=7200, Tolerance=1e-8), Documentation(info="<html>
<p>The evaporator slice (<code>Benches.Evaporator.Twin</code>) driven by a
feed reduction from 2 to 1.2 kg/s at 30 min, oscillating feed dry solids and
temperature, steam and next-effect pressures, and oscillating correction flows
into the three vessels. Six integrator states accumulate what crosses the
boundaries; the conservation laws say</p>
<ul>
<li><code>massInventory(t) - massInventory(0) = massIn - massOut</code>
(liquids, vapour spaces and the steam chest),</li>
<li><code>solidsInventory(t) - solidsInventory(0) = solidsIn - solidsOut</code>,</li>
<li><code>energyInventory(t) - energyInventory(0) = energyIn - energyOut</code>
for the liquid inventories (body, flash tank, condensate tank): the boundary
terms are the feed, the heat from the steam chest, the condensate entering
the tank, the correction flows, the vapour leaving each liquid, the product,
the condensate leaving and the heat losses. The pump's work is neglected by
the model, so it is not a term.</li>
</ul>
<p>The test <code>tests/test_evaporator_components.py</code> checks them from
the FMU's outputs.</p>
</html>"));
end SliceBalance;
