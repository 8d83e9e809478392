within TrackingBox.Evaporation;
connector LiquorPort_a "Liquor inlet port (design flow into the component); reads x and T from upstream"
  extends TrackingBox.Evaporation.LiquorPort;
end LiquorPort_a;
