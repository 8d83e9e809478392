"""Step tests on a small CasADi-built FMU whose steady-state gains are solved by hand.

The model (time in s)::

    dx1/dt = (a*u + z - x1 + 0.5*x2) / 5       y1 = x1
    dx2/dt = (b - x2 + 0.2*x1) / 10            y2 = x2
    dx3/dt = (c - x3) / 20                     y3 = x1**2,  y4 = x3
    dz/dt  = (1 - hold) * ki * (r - x1)        (PI-like integrator: holds when hold = 1)
    dw/dt  = d - 1                             y5 = w (never settles once d != 1)
    dL/dt  = (c - 1 + corr) / 2                y6 = L (a tank level: integrates any imbalance)
    ds/dt  = (1 - s) / 1000                    y7 = s + 3*x3 (a slow drift on top of dy7/dc = 3)

With z held constant the steady state is x1 = (a*u + z + 0.5*b) / 0.9,
x2 = b + 0.2*x1, so dy1/da = u/0.9, dy1/db = 0.5/0.9, dy2/da = 0.2*u/0.9,
dy2/db = 1 + 0.1/0.9 = 10/9, dy4/dc = 1 with a first-order time constant of 20 s.
Before freezing, the integrator drives x1 to r = 2, so y3 = x1**2 has the
secant gain 2*x1*dx1/da and the +/- step asymmetry 2*delta/(2*x1 + delta),
delta = (u/0.9) * (0.05 * (1.5 - 0.5)).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from trackingbox.analysis.executor import make_executor
from trackingbox.analysis.steptest import StepSettings, make_problem, operating_point, step_tests, time_to_63
from trackingbox.errors import AnalysisError


U = 1.5


OUTPUTS = {"Y1": "y1", "Y2": "y2", "Y3": "y3", "Y4": "y4"}
PARAMS = [("a", 1.0, 0.5, 1.5), ("b", 2.0, 1.0, 3.0), ("c", 1.0, 0.0, 2.0)]
FAST = dict(interval=1.0, window=50.0, tolerance=1e-6, max_time=2000.0)


def _problem(fmu, **kw):
    return make_problem(fmu, outputs=OUTPUTS, parameters=PARAMS, operating={"u": U},
                        ranges={t: 1.0 for t in OUTPUTS}, **kw)


@pytest.mark.parametrize(("workers", "warm"), [(1, True), (2, False)])
def test_gains_with_frozen_controller_match_hand_solution(step_fmu, workers, warm):
    prob = _problem(step_fmu, freeze={"hold": 1.0})
    settings = StepSettings(freeze=(("hold", 1.0),), warm_start=warm, **FAST)
    with make_executor(workers=workers) as ex:
        res = step_tests(prob, settings, ex)
    delta = 0.05 * 1.0
    expected = np.array([[U / 0.9, 0.5 / 0.9, 0.0],
                         [0.2 * U / 0.9, 10 / 9, 0.0],
                         [2 * 2.0 * U / 0.9, 2 * 2.0 * 0.5 / 0.9, 0.0],
                         [0.0, 0.0, 1.0]])
    assert np.allclose(res.gains, expected, atol=1e-4)
    assert np.allclose(res.deltas, [delta, 0.1, 0.1])
    # the integrator had brought x1 to its setpoint r = 2 before the freeze
    assert res.baseline[0] == pytest.approx(2.0, abs=1e-4)
    assert res.freeze_time < res.step_time
    # linear outputs: symmetric; y3 = x1**2: asymmetry 2*dl/(2*x1 + dl)
    dl = U / 0.9 * delta
    assert res.asymmetry[0, 0] < 1e-3
    assert res.asymmetry[2, 0] == pytest.approx(2 * dl / (2 * 2.0 + dl), rel=1e-3)
    assert math.isnan(res.asymmetry[0, 2])  # y1 does not respond to c at all
    assert res.time_constants[3, 2] == pytest.approx(20.0, abs=0.2)
    assert res.runs == 2 + 2 * 3  # baseline, reference run, +/- step per parameter


def test_without_freeze_the_active_controller_hides_the_gain(step_fmu):
    # no freeze: the integrator restores y1 = r after any step, so dy1/da -> 0
    res = step_tests(_problem(step_fmu), StepSettings(two_sided=False, **FAST))
    assert abs(res.gains[0, 0]) < 1e-3
    assert res.gains[3, 2] == pytest.approx(1.0, abs=1e-4)
    assert np.all(np.isnan(res.gains_down))


def test_step_that_never_settles_names_parameter(step_fmu):
    prob = make_problem(step_fmu, outputs={"Y5": "y5"}, parameters=[("d", 1.0, 0.5, 1.5)],
                        ranges={"Y5": 1.0})
    with pytest.raises(AnalysisError) as info:
        step_tests(prob, StepSettings(interval=1.0, window=20.0, tolerance=1e-6, max_time=100.0))
    msg = str(info.value)
    assert "step of d" in msg and "did not settle" in msg and "y5 moved" in msg


def test_state_compensation_holds_an_integrating_level(step_fmu):
    # correction = K (L_ref - L): a step dc gives dL/dt = (dc + K (L_ref - L)) / 2 = 0 at
    # L = L_ref + dc / K, so the level settles with gain 1/K instead of ramping.
    K = 0.5
    prob = make_problem(step_fmu, outputs={"Y6": "y6", "Y4": "y4"}, parameters=[("c", 1.0, 0.0, 2.0)],
                        ranges={"Y6": 1.0, "Y4": 1.0}, compensation=[("y6", "corr", K)])
    res = step_tests(prob, StepSettings(**FAST))
    assert res.gains[0, 0] == pytest.approx(1 / K, rel=1e-4)
    # the correction is updated every interval T = 1 s (held in between), so the level error
    # shrinks by (1 - K T / 2) per interval: 63.2 % after ln(e^-1) / ln(0.75) = 3.48 intervals
    assert res.time_constants[0, 0] == pytest.approx(-1.0 / math.log(1 - K * 1.0 / 2), abs=0.1)
    assert res.gains[1, 0] == pytest.approx(1.0, rel=1e-4)
    # without compensation the level ramps and the step never settles
    plain = make_problem(step_fmu, outputs={"Y6": "y6"}, parameters=[("c", 1.0, 0.0, 2.0)], ranges={"Y6": 1.0})
    with pytest.raises(AnalysisError, match="y6 moved"):
        step_tests(plain, StepSettings(interval=1.0, window=20.0, tolerance=1e-6, max_time=100.0))


def test_drift_correction_removes_a_slow_residual_drift(step_fmu):
    # the baseline counts as settled once s moves < 0.01 per 50 s, i.e. with s ~ 0.8 still
    # creeping towards 1 (tau 1000 s); the step response of y7 must still be dy7/dc = 3.
    prob = make_problem(step_fmu, outputs={"Y7": "y7"}, parameters=[("c", 1.0, 0.0, 2.0)], ranges={"Y7": 1.0})
    settings = StepSettings(interval=1.0, window=50.0, tolerance=1e-5, baseline_tolerance=1e-2, max_time=3000.0)
    res = step_tests(prob, settings)
    assert res.baseline[0] < 3.0 + 0.9  # s had not reached 1 at the step
    assert res.gains[0, 0] == pytest.approx(3.0, rel=1e-3)
    assert res.time_constants[0, 0] == pytest.approx(20.0, abs=0.2)
    # without the reference run the drift never dies down within the tight step tolerance
    from dataclasses import replace

    with pytest.raises(AnalysisError, match="did not settle"):
        step_tests(prob, replace(settings, drift_correction=False, max_time=300.0))


def test_unknown_names_get_did_you_mean(step_fmu):
    with pytest.raises(AnalysisError) as info:
        make_problem(step_fmu, outputs={"Y1": "y11"}, parameters=[("aa", 1.0, 0.5, 1.5)],
                     freeze={"hodl": 1.0})
    msg = str(info.value)
    assert "'aa'" in msg and "did you mean 'a'" in msg
    assert "'y11'" in msg and "'hodl'" in msg and "'hold'" in msg


def test_operating_point_is_mean_of_first_hour():
    frame = pd.DataFrame({"time": [0.0, 1800.0, 3599.0, 3600.0, 7200.0],
                          "FI": [1.0, 2.0, 3.0, 100.0, 100.0]})
    assert operating_point(frame, {"FI": "u"}) == {"u": pytest.approx(2.0)}
    assert operating_point(frame, {"FI": "u"}, at=900.0) == {"u": pytest.approx(1.5)}
    with pytest.raises(AnalysisError, match="did you mean 'FI'"):
        operating_point(frame, {"FII": "u"})


def test_time_to_63_of_first_order_response():
    t = np.arange(100.0, 200.0, 0.5)
    y = 3.0 - 2.0 * np.exp(-(t - 100.0) / 12.0)  # from 1 to 3 with tau = 12 s
    assert time_to_63(t, y, 1.0, 3.0) == pytest.approx(12.0, abs=0.01)



def test_a_short_first_reference_run_gives_the_results_of_a_full_one(step_fmu):
    # the reference run is first recorded over 60 s only: the steps of c (y7 = slow + 3 x3, tau 20 s, drift
    # corrected) run past it, stop, and run again against references of 240 s and 960 s; every figure must be
    # what one reference over the whole max_time gives, and the gain the hand-solved dy7/dc = 3
    from dataclasses import replace

    prob = make_problem(step_fmu, outputs={"Y7": "y7", "Y1": "y1"}, parameters=[("c", 1.0, 0.0, 2.0),
                                                                                  ("a", 1.0, 0.5, 1.5)],
                        ranges={"Y7": 1.0, "Y1": 1.0}, operating={"u": U}, freeze={"hold": 1.0})
    settings = StepSettings(freeze=(("hold", 1.0),), interval=1.0, window=50.0, tolerance=1e-5,
                            baseline_tolerance=1e-2, max_time=3000.0)
    full = step_tests(prob, replace(settings, reference_horizon=3000.0))
    short = step_tests(prob, replace(settings, reference_horizon=60.0))
    for name in ("gains", "gains_up", "gains_down", "asymmetry", "time_constants", "baseline"):
        np.testing.assert_array_equal(getattr(short, name), getattr(full, name), err_msg=name)
    assert full.gains[0, 0] == pytest.approx(3.0, rel=1e-3)
    assert full.runs == 2 + 2 * 2
    assert short.runs > full.runs  # the extended references and the steps run again
    assert StepSettings().first_reference_horizon() == 12000.0  # max(20 windows of 600 s, 86400 s / 8)
    with pytest.raises(AnalysisError, match="reference_horizon"):
        StepSettings(reference_horizon=0.0)
