"""The linearised loops of ``scripts/_explain_evaporator_bands.py`` (issue 31), against hand-worked steady states
and against :func:`trackingbox.identify.bands.loops_noise`'s impulse responses (written separately)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from trackingbox.identify.bands import loops_noise

_spec = importlib.util.spec_from_file_location(
    "_explain_evaporator_bands", Path(__file__).resolve().parents[1] / "scripts" / "_explain_evaporator_bands.py")
explain = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(explain)

TS = 10.0


def _run(gains, loops, drive, step=None, hold=None, start=None):
    n, m = drive.shape
    return explain.simulate(np.asarray(gains, float), loops, TS, drive, np.zeros((n, m)) if step is None else step,
                            np.zeros((n, m), bool) if hold is None else hold,
                            np.zeros(m) if start is None else np.asarray(start, float))


def test_constant_error_at_the_truth_is_absorbed_as_error_over_gain():
    # the twin at the truth reads a tag 0.01 below its measurement: the PI loop's integral drives the tag's
    # error to 0, which takes p - truth = 0.01 / g (g = -2), so truth - p = 0.005
    g, tau, lam = -2.0, 600.0, 3.0
    loops = [(g, tau, 1.0 / (abs(g) * lam), tau)]
    out = _run([[g]], loops, np.full((3000, 1), 0.01))
    assert out[-1, 0] == pytest.approx(-(0.01 / g), rel=1e-6)


def test_ramp_of_the_truth_lags_by_rate_times_lambda_tau():
    # SIMC (Ti = tau, Kc = 1/(|g| lambda)): the closed loop is first order with time constant lambda tau, so a
    # truth moving at rate r is r lambda tau ahead once settled (continuous time; the sampled loop within 1 %)
    g, tau, lam, r = -2.0, 600.0, 3.0, 1e-4
    loops = [(g, tau, 1.0 / (abs(g) * lam), tau)]
    n = 6000
    out = _run([[g]], loops, np.zeros((n, 1)), step=np.full((n, 1), r * TS))
    assert out[-1, 0] == pytest.approx(r * lam * tau, rel=0.01)


def test_a_held_loop_is_frozen_while_the_truth_moves_on():
    g, tau = -2.0, 600.0
    loops = [(g, tau, 1.0 / (abs(g) * 3.0), tau)]
    n, r = 400, 1e-4
    hold = np.zeros((n, 1), bool)
    hold[100:200] = True
    out = _run([[g]], loops, np.zeros((n, 1)), step=np.full((n, 1), r * TS), hold=hold)
    # in hold p does not move: the miss grows by exactly the truth's motion
    assert out[199, 0] - out[99, 0] == pytest.approx(100 * r * TS, rel=1e-12)


def test_two_loops_impulse_responses_match_loops_noise():
    # an impulse of error on each tag: the sum of squares of each parameter's response is loops_noise's acf at lag 0
    # (the impulse one row in: a loop's first row has no previous error, so no proportional kick)
    gains = np.array([[-2.0, 0.5], [0.8, 1.5]])
    loops = [(-2.0, 600.0, 1.0 / 6.0, 600.0), (1.5, 300.0, 1.0 / 4.5, 300.0)]
    acf = loops_noise(gains, loops, TS)
    assert acf is not None
    for k in range(2):
        drive = np.zeros((20000, 2))
        drive[1, k] = 1.0
        out = _run(gains, loops, drive)
        for j in range(2):
            assert float(np.sum(out[:, j] ** 2)) == pytest.approx(acf[j, k, 0], rel=1e-6)
