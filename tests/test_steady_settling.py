"""Steady states by following the model's own settling (``trackingbox.fmu.steady``).

The expectations are worked by hand (the roots of a cubic) and checked against scipy's Radau
integrator run to a late time: an implementation other than the BDF run under test.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import root

from trackingbox.fmu.steady import settle_by_integration


def bistable(z: np.ndarray) -> np.ndarray:
    """A fast state x that follows y**2 within a millisecond, and a slow y with stable steady states at
    y = 1 and y = 3 and an unstable one at y = 2 between them (time scale about 500 s)."""
    x, y = z
    return np.array([1e3 * (y * y - x), -2e-3 * (y - 1) * (y - 2) * (y - 3) + 1e-4 * (x - y * y)])


def test_ends_where_the_model_settles_not_at_the_nearest_root():
    start = [0.0, 2.2]  # above the unstable y = 2: the model settles at y = 3, x = 9
    reference = solve_ivp(lambda _t, z: bistable(z), (0.0, 1e5), start, method="Radau", rtol=1e-10, atol=1e-12)
    assert reference.y[:, -1] == pytest.approx([9.0, 3.0], abs=1e-6)
    # a root finder from the same start goes to the unstable root y = 2 (x = 4): why settle() integrates
    assert root(bistable, start, method="hybr").x == pytest.approx([4.0, 2.0], abs=1e-6)
    run = settle_by_integration(bistable, start, 1e-10)
    assert run.converged and run.message == ""
    assert run.z == pytest.approx([9.0, 3.0], abs=1e-6)
    assert np.max(np.abs(run.rates)) <= 1e-10
    # below y = 2 it settles at y = 1, x = 1
    assert settle_by_integration(bistable, [5.0, 1.8], 1e-10).z == pytest.approx([1.0, 1.0], abs=1e-6)


def test_a_state_already_settled_is_left_as_it_is():
    run = settle_by_integration(bistable, [9.0, 3.0], 1e-10)
    assert run.converged and run.time == 0.0 and run.z.tolist() == [9.0, 3.0]


def test_an_integrating_state_never_settles_and_says_so():
    # der(level) = 0.5: no steady state; the run gives up at its end time with the rate unchanged
    run = settle_by_integration(lambda z: np.array([0.5]), [2.0], 1e-9, t_max=1e6)
    assert not run.converged and run.rates.tolist() == [0.5]
    assert run.message == "still moving after 1e+06 s"


def test_rates_that_turn_nan_on_the_way_end_the_run_where_they_were_finite_and_say_so():
    # a body boiled dry at a fixed rate: 0.5 kg/s of its 2 kg until t = 4 s (by hand), no rate once empty
    run = settle_by_integration(lambda z: np.where(z > 0.0, -0.5, np.nan), [2.0], 1e-9)
    assert not run.converged and run.nonfinite == (0,)
    assert "non-finite" in run.message
    # the last states with finite rates lie on the hand-solved trajectory, before it empties
    assert 0.0 < run.time <= 4.0 and run.z[0] > 0.0
    assert run.z[0] == pytest.approx(2.0 - 0.5 * run.time, abs=1e-6)
    assert run.rates.tolist() == [-0.5]
