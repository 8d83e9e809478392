"""trackingbox: turn a Modelica process model into a tracking simulator.

A tracking simulator runs beside the plant with the plant's control inputs and
keeps adjusting selected model parameters so that its simulated sensors follow
the plant's measurements.
"""
from __future__ import annotations

__version__ = "0.1.0"
