within TrackingBox.Fluid.Validation;
model HeatedLoop "Tank, pump, pipe, valve, heating unit and heat exchanger in a closed loop"
  extends TrackingBox.Icons.Example;
  TrackingBox.Fluid.OpenTank tank(nPorts_a=1, A=0.2, zInlet=1.5, level_start=0.8, T_start=323.15) "Open tank";
  TrackingBox.Fluid.Pump pump(quadratic=true, VFlowDesign=8e-5, uRise=40000) "Pump";
  TrackingBox.Fluid.Pipe pipe(quadratic=true, k=0.005, m_flow_nominal=0.08) "Pipe";
  TrackingBox.Fluid.Valve valve(KvMax=1) "Valve";
  TrackingBox.Fluid.HeatingUnit heater(kht=1050, A=0.15, V=0.02, T_start=323.15, use_THeat_in=false, THeatFixed=413.15) "Heating unit";
  TrackingBox.Fluid.HeatExchanger hex(n=5, kht=1000, A=0.45, V1=0.005, V2=0.005, T1_start=323.15, T2_start=313.15) "Heat exchanger";
  TrackingBox.Fluid.Sources.MassFlowSource coldIn(m_flow=0.07, T=313.15) "Cold stream";
  TrackingBox.Fluid.Sources.PressureSink coldOut "Cold stream sink";
equation
  pump.speed = 0.9 + 0.1*sin(2*3.14159*time/1000);
  valve.opening = 0.8;
  connect(tank.port_b, pump.port_a);
  connect(pump.port_b, pipe.port_a);
  connect(pipe.port_b, valve.port_a);
  connect(valve.port_b, heater.port_a);
  connect(heater.port_b, hex.port_a1);
  connect(hex.port_b1, tank.port_a[1]);
  connect(coldIn.port, hex.port_a2);
  connect(hex.port_b2, coldOut.port);
  annotation (experiment(StopTime=3000, Tolerance=1e-6), Documentation(info="<html>
<p>Closed loop: the tank level stays constant (no net flow); the loop
temperature rises until the heating unit's input equals the heat given to the
cold stream plus tank losses.</p>
</html>"));
end HeatedLoop;
