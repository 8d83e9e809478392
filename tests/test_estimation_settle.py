"""The global search's settle rule: it stops once its best point stays put, inside the basin of the minimum."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from trackingbox import estimation
from trackingbox.estimation import search
from trackingbox.checkpoint import Journal
from trackingbox.errors import EstimationError

MINIMUM = np.array([909.0, 0.37])  # where the cost below is smallest (by construction)


class _Quadratic:
    """A smooth, single-basin cost with its minimum at :data:`MINIMUM`, counting its evaluations."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, x: np.ndarray) -> float:
        self.calls += 1
        scaled = (np.asarray(x, dtype=float) - MINIMUM) / np.array([1000.0, 1.0])
        return float(0.02 + np.sum(scaled ** 2))


def _problem() -> estimation.Problem:
    return estimation.Problem(twin=Path("twin.fmu"), names=("hx.kht", "f"), start=np.array([1000.0, 0.5]),
                              lower=np.array([500.0, 0.0]), upper=np.array([1500.0, 1.0]), fixed={},
                              outputs={"T": "T"}, sample_time=10.0, warmup=0.0)


def _search(settle: float, maxiter: int = 40):
    problem, cost = _problem(), _Quadratic()
    start_cost = cost(problem.start)
    x, best, evaluations = search.global_search(
        cost, cost, problem, None, Journal(None, {"test": 1}), seed=0, maxiter=maxiter, popsize=None,
        start_cost=start_cost, history=[], best=(problem.start.copy(), start_cost), progress=None,
        checkpoint=lambda *a: None, settle=settle)
    return x, best, evaluations


def test_settled_search_stops_early_near_the_minimum():
    x_full, _, n_full = _search(settle=0.0)
    x, cost, n = _search(settle=estimation.GLOBAL_SETTLE)
    span = _problem().upper - _problem().lower
    assert n < n_full / 2, (n, n_full)  # it stopped well before differential evolution converged
    # inside the basin: within a few settle widths of the true minimum (the refinement's start)
    assert np.all(np.abs(x - MINIMUM) / span <= estimation.GLOBAL_SETTLE), x
    assert cost < 0.02 + 3e-3
    # without the rule the search runs to differential evolution's own stop, closer still
    assert np.all(np.abs(x_full - MINIMUM) / span <= 1e-2), x_full


def test_settle_out_of_range_is_refused(tmp_path):
    class _Spec:  # estimate refuses the setting before it reads anything
        parameters = [object()]
        path = tmp_path / "spec.toml"
        windows: dict = {}
        sample_time = 10.0

    with pytest.raises(EstimationError, match="settle must be a fraction in"):
        estimation.estimate(_Spec(), settle=1.5)
