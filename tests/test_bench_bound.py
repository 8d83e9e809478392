"""The benchmarks' no-Python lower bound (``scripts/_bound.py`` and its C driver).

Judged against the closed-form solution of the first-order twin of
``_fixtures_tracking`` (``der(x) = (u - x)/TAU - k*x``, ``y = x``, ``x(0) = 38``),
with a constant and a ramping input, and against trackingbox's own
model-exchange stepper on the same FMU (same CVODE settings: the same trajectory).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_tracking import TAU

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))

from _bound import run_bound  # noqa: E402

X0 = 38.0


def closed_form_ramp(t: np.ndarray, k: float, u0: float, rate: float) -> np.ndarray:
    """x(t) for u = u0 + rate*t: x = A + B t + (x0 - A) exp(-a t), a = 1/TAU + k (solved by hand)."""
    a = 1.0 / TAU + k
    b = rate / (TAU * a)
    big_a = (u0 / TAU - b) / a
    return big_a + b * t + (X0 - big_a) * np.exp(-a * t)


@pytest.mark.compile
@pytest.mark.parametrize("rate", [0.0, 0.01])
def test_bound_matches_closed_form(first_order_fmu: Path, rate: float) -> None:
    k = 0.005
    grid = np.arange(0.0, 1201.0, 10.0)
    inputs = pd.DataFrame({"time": grid, "u": 60.0 + rate * grid})  # linear in t: interpolation is exact
    bound = run_bound(first_order_fmu, grid=grid, outputs=["y"], parameters={"k": k}, inputs=inputs)
    expected = closed_form_ramp(grid, k, 60.0, rate)
    # rtol 1e-6 with atol 1e-6 (nominal 1): a few 1e-5 K on values near 50 K is CVODE's error
    assert np.max(np.abs(bound.outputs[:, 0] - expected)) < 1e-3
    assert bound.steps > 0 and bound.rhs >= bound.steps
    assert bound.cpu >= 0.0 and bound.wall >= 0.0


@pytest.mark.compile
def test_bound_is_the_stepper_trajectory(first_order_fmu: Path) -> None:
    from trackingbox.fmu import FMUModel

    grid = np.arange(0.0, 3001.0, 10.0)
    u = 50.0 + 10.0 * np.sin(grid / 300.0)
    inputs = pd.DataFrame({"time": grid, "u": u})
    bound = run_bound(first_order_fmu, grid=grid, outputs=["y"], parameters={"k": 0.004}, inputs=inputs)
    model = FMUModel(first_order_fmu, tolerance=1e-6)
    try:
        stepper = model.stepper(start_time=0.0, parameters={"k": 0.004}, inputs=inputs)
        ys = [float(stepper.get(["y"])[0])]
        for t in grid[1:]:
            stepper.step(float(t))
            ys.append(float(stepper.get(["y"])[0]))
    finally:
        model.close()
    # same CVODE library, method, tolerances, largest step and input interpolation: the same numbers
    # up to the order of floating-point operations
    assert np.max(np.abs(np.array(ys) - bound.outputs[:, 0])) < 1e-9 * 60.0
