"""A free state whose start value is 0 in a nonlinear block of the initialisation problem (issue 35: MSL
``Fluid.Examples.NonCircularPipes``' pipe volumes and ``PumpingSystem``'s tank, whose states here are
mass and internal energy, initialised by their medium's pressure and enthalpy) is found from the
initial equations together with the model's own equations, as a Modelica tool sorts its initialisation
problem: from p and h the mass and energy follow explicitly. Newton in (m, U) from (0, 0) through the
model's loop for (p, h) found no solution (the density cannot be 0). Expectation: hand-worked."""
from __future__ import annotations

import math

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

VESSEL = """model VesselInit "a vessel whose states are its mass and internal energy, initialised by p and h"
  parameter Real V = 2;
  Real m "no start value";
  Real U "no start value";
  Real p(start = 1);
  Real h(start = 20);
  Real d(start = 1);
initial equation
  p = 2;
  h = 30;
equation
  der(m) = -0.1*m;
  der(U) = -0.1*U;
  m = V*d;
  d = exp(0.1*sqrt(p) + 0.01*h);
  U = m*(h - p/d);
end VesselInit;
"""


def test_a_vessel_initialised_by_pressure_and_enthalpy_starts_at_its_mass_and_energy(tmp_path):
    src = tmp_path / "VesselInit.mo"
    src.write_text(VESSEL)
    res = compile_model(src, "VesselInit", backend="embedded", output=tmp_path / "v.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["m", "U", "p", "h"],
                            relative_tolerance=1e-9)
    d0 = math.exp(0.1 * math.sqrt(2.0) + 0.3)
    m0, u0 = 2 * d0, 2 * d0 * (30 - 2 / d0)
    assert abs(out["p"][0] - 2.0) < 1e-9 and abs(out["h"][0] - 30.0) < 1e-9
    decay = np.exp(-0.1 * out["time"])
    assert np.allclose(out["m"], m0 * decay, rtol=1e-6) and np.allclose(out["U"], u0 * decay, rtol=1e-6)
