"""Test FMUs for the analysis tests (step tests, Sobol), built with CasADi.

The model is described in ``test_steptest.py``'s module docstring.
"""
from __future__ import annotations

import os

import pytest


def build_step_fmu(directory) -> str:
    """The FMU described in the module docstring (FMI 3.0 model exchange, via CasADi)."""
    casadi = pytest.importorskip("casadi", reason="CasADi builds the test FMU")
    import fmpy

    dae = casadi.DaeBuilder("steptwin")
    a = dae.add("a", "parameter", "tunable", {"start": 1.0, "min": 0.5, "max": 1.5})
    b = dae.add("b", "parameter", "tunable", {"start": 2.0, "min": 1.0, "max": 3.0})
    c = dae.add("c", "parameter", "tunable", {"start": 1.0, "min": 0.0, "max": 2.0})
    d = dae.add("d", "parameter", "tunable", {"start": 1.0, "min": 0.5, "max": 1.5})
    ki = dae.add("ki", "parameter", "tunable", {"start": 0.2})
    r = dae.add("r", "parameter", "tunable", {"start": 2.0})
    u = dae.add("u", "input", {"start": 1.0})
    hold = dae.add("hold", "input", {"start": 0.0})
    x1 = dae.add("x1", "local", "continuous", {"start": 0.0, "initial": "exact"})
    x2 = dae.add("x2", "local", "continuous", {"start": 0.0, "initial": "exact"})
    x3 = dae.add("x3", "local", "continuous", {"start": 0.0, "initial": "exact"})
    z = dae.add("z", "local", "continuous", {"start": 0.0, "initial": "exact"})
    w = dae.add("w", "local", "continuous", {"start": 0.0, "initial": "exact"})
    ys = [dae.add(n, "output", {}) for n in ("y1", "y2", "y3", "y4", "y5")]
    dae.eq(dae.der(x1), (a * u + z - x1 + 0.5 * x2) / 5.0)
    dae.eq(dae.der(x2), (b - x2 + 0.2 * x1) / 10.0)
    dae.eq(dae.der(x3), (c - x3) / 20.0)
    dae.eq(dae.der(z), (1 - hold) * ki * (r - x1))
    dae.eq(dae.der(w), d - 1.0)
    for y, expr in zip(ys, (x1, x2, x1 * x1, x3, w)):
        dae.eq(y, expr)
    cwd = os.getcwd()
    os.chdir(directory)
    try:
        files = dae.export_fmu({"no_warning": True})
        files = dae.compile_fmu(files, {"include_dirs": [os.path.join(os.path.dirname(fmpy.__file__), "c-code")]})
        path = dae.pack_fmu(files, {})
    finally:
        os.chdir(cwd)
    return str(directory / path)
