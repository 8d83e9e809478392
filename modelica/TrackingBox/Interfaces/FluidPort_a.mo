within TrackingBox.Interfaces;
connector FluidPort_a "Inlet port (design flow into the component); reads T from upstream"
  extends FluidPort;
end FluidPort_a;
