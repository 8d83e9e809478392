"""Package data: the TrackingBox Modelica library (shipped with the Python package)."""
