"""Pairing with the controllers frozen, judged with the gains of the twin as the data were recorded.

The RGA takes the frozen step tests' gains (the structure); the reach and
predicted-tracking checks take the gains of step tests with nothing frozen,
because the data were recorded with the plant's controllers active (issue 15).
Every expectation below is worked by hand from ``reach = |g| x range / |offset|``
and the first-order prediction of :func:`~trackingbox.analysis.offsets.predict_tracking`.
"""
from __future__ import annotations

import numpy as np
import pytest

from trackingbox.analysis.offsets import Residuals
from trackingbox.analysis.pairing import DataChecks, choose_pairs, recording_time_constants
from trackingbox.errors import AnalysisError

N = 400
DT = 10.0


def _residuals(rows: dict[str, np.ndarray]) -> Residuals:
    names = tuple(rows)
    meas = np.array([rows[k] for k in names])
    return Residuals(names, DT * np.arange(N), meas, np.zeros_like(meas), DT)


def _case():
    rng = np.random.default_rng(3)
    # a pressure P and a temperature T with offsets 1900 Pa and 0.5 K (noise 20 Pa, 0.02 K)
    res = _residuals({"P": 1900.0 + rng.normal(0, 20.0, N), "T": 0.5 + rng.normal(0, 0.02, N)})
    # frozen (structure): k moves P by 1.6e5 Pa per unit, kht moves T by 0.01 K per unit; both start
    # mid-range with 0.005 (k) and 100 (kht) left upward
    frozen = np.array([[1.6e5, 0.0], [0.0, 0.01]])
    # recorded way (controllers active): the loop that holds another tag speeds the pump up, so the
    # pressure gain is 3.7x the frozen one (5.9e5, the heat-production bench's order)
    recording = np.array([[5.9e5, 0.0], [0.0, 0.012]])
    bounds = [(0.005, 0.0001, 0.01), (1000.0, 850.0, 1100.0)]
    return res, frozen, recording, bounds


#: scaling: tag ranges 5 kPa and 5 K, parameter bound ranges (the pair stage's scaling)
SCALE = {"variable_ranges": [5000.0, 5.0], "parameter_ranges": [0.0099, 250.0]}


def test_frozen_gain_alone_cannot_reach_the_recorded_offset():
    res, frozen, _, bounds = _case()
    # reach by hand: 1.6e5 x 0.005 = 800 Pa against 1900 Pa -> 0.42 < 0.5: P is left out
    p = choose_pairs(frozen, ["P", "T"], ["k", "kht"], time_constants=[[5.0, 60.0]] * 2, residuals=res, **SCALE,
                     bounds=bounds, checks=DataChecks())
    assert {(x.variable, x.parameter) for x in p.pairs} == {("T", "kht")}
    assert p.reach[0, 0] == pytest.approx(800.0 / 1900.0, rel=0.02)
    assert "close its offset" in dict(p.left_out)["P"]


def test_recording_gains_judge_reach_and_the_rga_keeps_the_frozen_structure():
    res, frozen, recording, bounds = _case()
    p = choose_pairs(frozen, ["P", "T"], ["k", "kht"], time_constants=[[5.0, 60.0]] * 2, residuals=res, **SCALE,
                     bounds=bounds, checks=DataChecks(), check_gains=recording,
                     check_time_constants=[[8.0, 90.0]] * 2)
    assert {(x.variable, x.parameter) for x in p.pairs} == {("P", "k"), ("T", "kht")}
    # reach by hand with the recorded gain: 5.9e5 x 0.005 = 2950 Pa against 1900 Pa
    assert p.reach[0, 0] == pytest.approx(2950.0 / 1900.0, rel=0.02)
    # the RGA and the scaled gains are the frozen ones
    assert np.allclose(p.gains, frozen)
    by_var = {x.variable: x for x in p.pairs}
    # the written gain is the larger in magnitude (recorded here), with its time constant
    assert by_var["P"].gain == pytest.approx(5.9e5) and by_var["P"].time_constant == pytest.approx(8.0)
    assert by_var["T"].gain == pytest.approx(0.012) and by_var["T"].time_constant == pytest.approx(90.0)
    # constant offset c from the first sample, a first-order loop with tau (recorded + dt/2) sampled at
    # dt: the error left at sample k is c q^(k+1/2), q = exp(-dt/tau), so the transient's share of the
    # mean square over N samples is sum q^(2k+2)/N = q2/(1-q2)/N (q2 = q^2), plus the noise (sigma/c)^2
    for tag, tau, c, sigma in (("P", 8.0 + 5.0, 1900.0, 20.0), ("T", 90.0 + 5.0, 0.5, 0.02)):
        q2 = np.exp(-2 * DT / tau)
        hand = np.sqrt(q2 / (1 - q2) / N + (sigma / c) ** 2)
        assert by_var[tag].predicted_ratio == pytest.approx(hand, rel=0.1), tag


def test_a_pair_whose_frozen_and_recorded_gains_differ_in_sign_is_not_chosen():
    res, frozen, recording, bounds = _case()
    flipped = recording.copy()
    flipped[1, 1] = -0.012
    p = choose_pairs(frozen, ["P", "T"], ["k", "kht"], time_constants=[[5.0, 60.0]] * 2, residuals=res, **SCALE,
                     bounds=[bounds[0], (1000.0, 850.0, 1150.0)], checks=DataChecks(), check_gains=flipped)
    assert {(x.variable, x.parameter) for x in p.pairs} == {("P", "k")}
    assert "one sign" in dict(p.left_out)["T"]


def test_bad_recording_gains_are_named():
    res, frozen, _, bounds = _case()
    with pytest.raises(AnalysisError, match="data checks have shape"):
        choose_pairs(frozen, ["P", "T"], ["k", "kht"], residuals=res, bounds=bounds, **SCALE, check_gains=[[1.0]])
    with pytest.raises(AnalysisError, match="'T' to 'k' is not finite"):
        choose_pairs(frozen, ["P", "T"], ["k", "kht"], residuals=res, bounds=bounds,
                     check_gains=[[1.0, 0.0], [np.nan, 1.0]])


def test_recording_time_constants_fall_back_where_unmeasured():
    assert recording_time_constants([[10.0, 20.0]], [[0.0, 30.0]]).tolist() == [[10.0, 30.0]]


def _hidden_case(recording):
    """y is seen with the controllers frozen (a moves it); u, a controller's output, only with them active."""
    rng = np.random.default_rng(5)
    res = _residuals({"y": 1.0 + rng.normal(0, 0.01, N), "u": 0.2 + rng.normal(0, 0.002, N)})
    frozen = np.array([[1.0, 0.5], [0.0, 0.0]])
    bounds = [(0.0, -5.0, 5.0), (0.0, -5.0, 5.0)]
    first = choose_pairs(frozen, ["y", "u"], ["a", "b"], time_constants=[[10.0, 10.0]] * 2, residuals=res,
                         bounds=bounds, checks=DataChecks(), check_gains=recording,
                         check_time_constants=[[10.0, 10.0]] * 2)
    return first, res, bounds


def test_a_controller_output_the_freeze_hides_is_paired_from_the_recorded_gains():
    from trackingbox.analysis.pairing import complete_with_recording

    # recorded: a moves y by 0.8, b moves the controller output u by 2 and y not at all (its loop
    # compensates): the recorded RGA over (y, u) x (a, b) is the identity
    recording = np.array([[0.8, 0.0], [0.0, 2.0]])
    first, res, bounds = _hidden_case(recording)
    assert [(p.variable, p.parameter) for p in first.pairs] == [("y", "a")]
    assert "no candidate parameter moves it" in dict(first.left_out)["u"]
    done = complete_with_recording(first, recording, time_constants=[[10.0, 10.0]] * 2,
                                   variable_ranges=[1.0, 1.0], parameter_ranges=[10.0, 10.0], residuals=res,
                                   bounds=bounds, checks=DataChecks())
    assert [(p.variable, p.parameter, p.rga_from) for p in done.pairs] == [("y", "a", "structure"),
                                                                          ("u", "b", "recording")]
    u = done.pairs[1]
    assert u.lambda_ == pytest.approx(1.0) and u.gain == pytest.approx(2.0)
    # u's offset 0.2 needs b = 0.1 of 5 available; constant offset, loop of 15 s at 10 s samples:
    # the transient's share by hand as in the test above (q2 = exp(-20/15)) plus noise (0.002/0.2)^2
    q2 = np.exp(-2 * DT / 15.0)
    assert u.predicted_ratio == pytest.approx(np.sqrt(q2 / (1 - q2) / N + 0.01**2), rel=0.1)
    assert {n for n, _ in done.left_out} == set()


def test_a_hidden_tag_whose_recorded_partner_the_structure_took_stays_out_with_that_reason():
    from trackingbox.analysis.pairing import complete_with_recording

    # recorded: u moves mostly with a (2 per unit), y mostly with b: the recorded RGA pairs u with a,
    # which the frozen structure gave y; the frozen pairs are kept and u is left out, saying so
    recording = np.array([[0.8, 2.0], [2.0, 0.1]])
    first, res, bounds = _hidden_case(recording)
    done = complete_with_recording(first, recording, time_constants=[[10.0, 10.0]] * 2,
                                   variable_ranges=[1.0, 1.0], parameter_ranges=[10.0, 10.0], residuals=res,
                                   bounds=bounds, checks=DataChecks())
    assert [(p.variable, p.parameter) for p in done.pairs] == [("y", "a")]
    why = dict(done.left_out)["u"]
    assert why.startswith("no parameter moves it with the controllers frozen") and "pairs with y" in why
