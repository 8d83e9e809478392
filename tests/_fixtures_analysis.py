"""Test FMUs for the analysis tests (step tests, Sobol), built with CasADi.

The model is described in ``test_steptest.py``'s module docstring.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from _fixtures_casadi import build_casadi_fmu


def build_step_fmu(directory) -> str:
    """The FMU described in the module docstring (FMI 3.0 model exchange, via CasADi)."""
    pytest.importorskip("casadi", reason="CasADi builds the test FMU")
    state = ("local", "continuous")
    path = build_casadi_fmu(Path(directory), "steptwin", variables=[
        ("a", ("parameter", "tunable"), {"start": 1.0, "min": 0.5, "max": 1.5}),
        ("b", ("parameter", "tunable"), {"start": 2.0, "min": 1.0, "max": 3.0}),
        ("c", ("parameter", "tunable"), {"start": 1.0, "min": 0.0, "max": 2.0}),
        ("d", ("parameter", "tunable"), {"start": 1.0, "min": 0.5, "max": 1.5}),
        ("ki", ("parameter", "tunable"), {"start": 0.2}),
        ("r", ("parameter", "tunable"), {"start": 2.0}),
        ("u", ("input",), {"start": 1.0}),
        ("hold", ("input",), {"start": 0.0}),
        ("corr", ("input",), {"start": 0.0}),
        ("x1", state, {"start": 0.0, "initial": "exact"}),
        ("x2", state, {"start": 0.0, "initial": "exact"}),
        ("x3", state, {"start": 0.0, "initial": "exact"}),
        ("z", state, {"start": 0.0, "initial": "exact"}),
        ("w", state, {"start": 0.0, "initial": "exact"}),
        ("level", state, {"start": 1.0, "initial": "exact"}),
        ("slow", state, {"start": 0.0, "initial": "exact"}),
        *((n, ("output",), {}) for n in ("y1", "y2", "y3", "y4", "y5", "y6", "y7")),
    ], equations=[
        ("der(x1)", "(a * u + z - x1 + 0.5 * x2) / 5.0"),
        ("der(x2)", "(b - x2 + 0.2 * x1) / 10.0"),
        ("der(x3)", "(c - x3) / 20.0"),
        ("der(z)", "(1 - hold) * ki * (r - x1)"),
        ("der(w)", "d - 1.0"),
        ("der(level)", "(c - 1.0 + corr) / 2.0"),
        ("der(slow)", "(1.0 - slow) / 1000.0"),
        *zip(("y1", "y2", "y3", "y4", "y5", "y6", "y7"),
             ("x1", "x2", "x1 * x1", "x3", "w", "level", "slow + 3.0 * x3")),
    ])
    return str(path)


def write_pair_case(directory, fmu: str, *, u: float = 1.5):
    """A spec.toml + measurements.csv around the step-test FMU: FI drives u, Y1/Y2 measure y1/y2.

    Returns the spec path. The measured ranges (0.2 for Y1, 0.4 for Y2) only
    scale the gains; the pairing of a square system does not depend on them.
    """
    import shutil

    import numpy as np

    shutil.copy(fmu, directory / "twin.fmu")
    t = np.arange(0.0, 7200.0, 60.0)
    lines = ["time,FI,Y1,Y2"] + [f"{x:g},{u:g},{2.0 + 0.1 * np.sin(x / 600):.6f},{2.4 + 0.2 * np.cos(x / 900):.6f}"
                                 for x in t]
    (directory / "measurements.csv").write_text("\n".join(lines) + "\n")
    spec = directory / "spec.toml"
    spec.write_text(
        'twin = "twin.fmu"\nmeasurements = "measurements.csv"\nsample_time = 1.0\n\n'
        '[inputs]\n"FI" = "u"\n\n[outputs]\n"Y1" = "y1"\n"Y2" = "y2"\n\n'
        '[[parameters]]\nname = "a"\nstart = 1.0\nmin = 0.5\nmax = 1.5\n\n'
        '[[parameters]]\nname = "b"\nstart = 2.0\nmin = 1.0\nmax = 3.0\n\n'
        '[windows]\ntraining = [0.0, 3600.0]\nvalidation = [3600.0, 7200.0]\n')
    return spec
