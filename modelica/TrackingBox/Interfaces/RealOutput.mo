within TrackingBox.Interfaces;
connector RealOutput = output Real "Connector with one output signal of type Real";
