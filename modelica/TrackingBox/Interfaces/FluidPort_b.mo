within TrackingBox.Interfaces;
connector FluidPort_b "Outlet port (design flow out of the component); sets T"
  extends FluidPort;
end FluidPort_b;
