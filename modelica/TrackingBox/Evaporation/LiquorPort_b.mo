within TrackingBox.Evaporation;
connector LiquorPort_b "Liquor outlet port (design flow out of the component); sets x and T"
  extends TrackingBox.Evaporation.LiquorPort;
end LiquorPort_b;
