"""Automatic pairing by relative gain: hand-solved cases."""
from __future__ import annotations

import math

import numpy as np
import pytest

from trackingbox.analysis.pairing import Pair, choose_pairs
from trackingbox.errors import AnalysisError


def _pairs(p):
    return {x.variable: x.parameter for x in p.pairs}


def _reason(p, name):
    return dict(p.left_out)[name]


def test_wood_berry_pairs_diagonal_and_flags_negative_elements():
    # lambda_11 = lambda_22 = 2.01, off-diagonal = 1 - 2.01 < 0
    G = [[12.8, -18.9], [6.6, -19.4]]
    p = choose_pairs(G, ["XD", "XB"], ["R", "S"], time_constants=[[16.7, 21.0], [10.9, 14.4]])
    assert p.pairs == (Pair("XD", "R", pytest.approx(2.0094, abs=1e-4), 12.8, 16.7),
                       Pair("XB", "S", pytest.approx(2.0094, abs=1e-4), -19.4, 14.4))
    assert p.left_out == ()
    assert any("negative" in w and "XD/S" in w and "XB/R" in w for w in p.warnings)


def test_off_diagonal_pairing_when_diagonal_is_negative():
    # G = [[1, 2], [3, 4]]: Lambda = [[-2, 3], [3, -2]]
    p = choose_pairs([[1.0, 2.0], [3.0, 4.0]], ["y1", "y2"], ["p1", "p2"])
    assert _pairs(p) == {"y1": "p2", "y2": "p1"}
    assert all(math.isclose(x.lambda_, 3.0) for x in p.pairs)


def test_large_relative_gain_is_flagged():
    # lambda_11 = 1 / (1 - 0.95) = 20
    p = choose_pairs([[1.0, 0.95], [1.0, 1.0]], ["y1", "y2"], ["p1", "p2"])
    assert _pairs(p) == {"y1": "p1", "y2": "p2"}
    assert math.isclose(p.pairs[0].lambda_, 20.0)
    assert any("large" in w and "y1/p1" in w for w in p.warnings)


def test_negligible_parameter_and_unmoved_variable_get_reasons():
    G = np.array([[2.0, 0.1, 1e-7, 0.0],
                  [0.2, 1.0, 0.0, 0.0],
                  [1e-8, 1e-8, 1e-9, 0.0]])
    p = choose_pairs(G, ["T1", "T2", "T3"], ["a", "b", "c", "d"])
    assert _pairs(p) == {"T1": "a", "T2": "b"}
    assert "negligible" in _reason(p, "c")
    assert "negligible" in _reason(p, "d")
    assert "moves it" in _reason(p, "T3")
    assert set(dict(p.left_out)) == {"c", "d", "T3"}


def test_scaling_decides_what_is_negligible():
    # raw gain 1e-5 K per Pa looks tiny, but the pump head range is 8000 Pa:
    # 1e-5 * 8000 / 2 K = 0.04 of the variable's range is not negligible.
    p = choose_pairs([[1e-5]], ["TI"], ["uRise"], variable_ranges=[2.0], parameter_ranges=[8000.0])
    assert _pairs(p) == {"TI": "uRise"}
    assert math.isclose(p.scaled_gains[0, 0], 0.04)


def test_tall_more_variables_than_parameters():
    # Lambda of [[1,0],[0,1],[1,1]] = [[2/3,0],[0,2/3],[1/3,1/3]] (solved by hand in test_rga)
    p = choose_pairs([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]], ["y1", "y2", "y3"], ["a", "b"])
    assert _pairs(p) == {"y1": "a", "y2": "b"}
    assert "taken by" in _reason(p, "y3")


def test_wide_single_variable_takes_strongest_parameter():
    # one row: lambda_j = g_j^2 / sum(g^2) = [1, 4, 16] / 21; closest to 1 is the largest gain
    p = choose_pairs([[1.0, -2.0, 4.0]], ["y"], ["a", "b", "c"])
    assert _pairs(p) == {"y": "c"}
    assert math.isclose(p.pairs[0].lambda_, 16 / 21)
    assert "not needed" in _reason(p, "a") and "not needed" in _reason(p, "b")


def test_dependent_parameter_is_left_out_not_crashing():
    # column b = 2 * column a: the two cannot be told apart
    p = choose_pairs([[1.0, 2.0, 0.0], [1.0, 2.0, 1.0]], ["y1", "y2"], ["a", "b", "c"])
    assert "linear combination" in _reason(p, "a")
    assert set(_pairs(p).values()) == {"b", "c"}
    assert math.isfinite(p.condition_number)


def test_nearly_parallel_parameters_are_told_apart_only_within_rank_tolerance():
    # p3's column [0.5, 0.001, 0.25] is half of p1's [1, 0, 0.5] up to an angle of ~0.0018 rad
    # (a valve in series with a pipe): not separable at the default tolerance (0.01 rad), so the
    # weaker of the two goes; separable when asked for 1e-6.
    G = [[1.0, 0.0, 0.5], [0.0, 1.0, 0.001], [0.5, 0.5, 0.25]]
    p = choose_pairs(G, ["F1", "F2", "P3"], ["p1", "p2", "p3"])
    reason = _reason(p, "p3")
    assert "parallel" in reason and "p1" in reason
    assert set(_pairs(p).values()) == {"p1", "p2"}
    assert p.condition_number < 100
    strict = choose_pairs(G, ["F1", "F2", "P3"], ["p1", "p2", "p3"], rtol=1e-6)
    assert not any("parallel" in r for _, r in strict.left_out)
    assert strict.condition_number > 100


def test_all_zero_gains():
    p = choose_pairs(np.zeros((2, 2)), ["y1", "y2"], ["a", "b"])
    assert p.pairs == ()
    assert len(p.left_out) == 4


def test_shape_mismatch_is_an_analysis_error():
    with pytest.raises(AnalysisError, match="shape"):
        choose_pairs([[1.0, 2.0]], ["y1", "y2"], ["a", "b"])


# ---------------------------------------------------------------- the pair command

@pytest.fixture(scope="module")
def pair_fmu(step_fmu):
    return step_fmu  # the session's step-test twin (conftest)


def test_pair_command_json_spec_and_report(tmp_path, pair_fmu, capsys):
    import json

    from _fixtures_analysis import write_pair_case
    from trackingbox.cli import main
    from trackingbox.spec import load_spec

    spec = write_pair_case(tmp_path, pair_fmu, u=1.5)
    # the made-up measurements are not the twin's: the gains and RGA are under test here
    rc = main(["pair", str(spec), "--freeze", "hold=1", "--json", "--workers", "1", "--report",
               str(tmp_path / "rep"), "--no-data-checks"])
    out = capsys.readouterr().out
    assert rc == 0
    doc = json.loads(out)
    # hand solution (see tests/test_steptest.py): G = [[u/0.9, 0.5/0.9], [0.2u/0.9, 10/9]], u = 1.5
    G = [[1.5 / 0.9, 0.5 / 0.9], [0.3 / 0.9, 10 / 9]]
    assert doc["gain_matrix"]["variables"] == ["Y1", "Y2"]
    assert doc["gain_matrix"]["parameters"] == ["a", "b"]
    assert np.allclose(doc["gain_matrix"]["values"], G, rtol=1e-4)
    lam = G[0][0] * G[1][1] / (G[0][0] * G[1][1] - G[0][1] * G[1][0])  # = 10/9
    assert np.allclose(doc["rga"]["values"], [[lam, 1 - lam], [1 - lam, lam]], rtol=1e-4)
    assert [(p["variable"], p["parameter"]) for p in doc["pairs"]] == [("Y1", "a"), ("Y2", "b")]
    assert doc["pairs"][0]["gain"] == pytest.approx(G[0][0], rel=1e-4)
    assert doc["sobol"] is None and doc["agreement"] is None
    assert doc["left_out"] == []
    written = load_spec(spec)
    assert [(p.variable, p.parameter) for p in written.pairs] == [("Y1", "a"), ("Y2", "b")]
    assert written.pairs[1].gain == pytest.approx(10 / 9, rel=1e-4)
    assert all(p.time_constant > 0 for p in written.pairs)
    for name in ("rga.png", "gains_scaled.png"):
        assert (tmp_path / "rep" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| Y1 | a |" in (tmp_path / "rep" / "pairing.md").read_text()


def test_pair_command_no_write_and_bad_freeze(tmp_path, pair_fmu, capsys):
    from _fixtures_analysis import write_pair_case
    from trackingbox.cli import main

    spec = write_pair_case(tmp_path, pair_fmu)
    before = spec.read_bytes()
    assert main(["pair", str(spec), "--freeze", "hold=1", "--workers", "1", "--no-write", "--one-sided",
                 "--no-data-checks"]) == 0
    assert spec.read_bytes() == before
    capsys.readouterr()
    assert main(["pair", str(spec), "--freeze", "hold"]) == 2
    assert "NAME=VALUE" in capsys.readouterr().err
    assert main(["pair", str(spec), "--freeze", "hodl=1", "--workers", "1"]) == 2
    assert "did you mean 'hold'" in capsys.readouterr().err
    assert spec.read_bytes() == before


@pytest.mark.compile
def test_pair_on_heat_exchanger_bench_is_physically_sensible(fmu_cache, tmp_path, capsys):
    # Counter-flow heat exchanger: a larger heat-transfer coefficient cools the hot outlet
    # and warms the cold outlet; the thesis pairs the hot outlet temperature with kht.
    import json

    from trackingbox.benches import make_bench
    from trackingbox.cli import main

    hx = "TrackingBox.Benches.HeatExchanger"
    case = make_bench("heat-exchanger", tmp_path / "case", seed=0, hours=2.0,
                      plant_fmu=fmu_cache(f"{hx}.Plant"), twin_fmu=fmu_cache(f"{hx}.Twin"))
    spec = tmp_path / "case" / "spec.toml"
    assert main(["pair", str(spec), "--json", "--no-write", "--workers", "1"]) == 0, case
    doc = json.loads(capsys.readouterr().out)
    gains = dict(zip(doc["gain_matrix"]["variables"], (row[0] for row in doc["gain_matrix"]["values"])))
    assert gains["TI-102"] < 0 < gains["TI-202"]
    assert [(p["variable"], p["parameter"]) for p in doc["pairs"]] == [("TI-102", "hx.kht")]
    assert doc["pairs"][0]["time_constant"] > 0


# ----------------------------------------------------------------- data-aware checks


def test_noise_sigma_recovers_known_noise_under_drift_and_steps():
    from trackingbox.analysis.offsets import noise_sigma

    rng = np.random.default_rng(7)
    n = 20000
    t = np.arange(n)
    slow = 3.0 * np.sin(2 * np.pi * t / 5000.0)           # process movement, 5000 samples a period
    steps = np.where((t // 2500) % 2 == 0, 0.0, 4.0)     # a few large setpoint steps
    for sigma in (0.05, 0.3):
        x = slow + steps + rng.normal(0.0, sigma, n)
        assert noise_sigma(x) == pytest.approx(sigma, rel=0.04)
    x = slow + rng.normal(0.0, 0.3, n)
    x[::7] = np.nan                                       # missing samples: differences across them unused
    assert noise_sigma(x) == pytest.approx(0.3, rel=0.04)
    assert math.isnan(noise_sigma([1.0, np.nan, 2.0]))


def test_offset_stats_of_a_constant_offset_with_noise():
    from trackingbox.analysis.offsets import offset_stats

    rng = np.random.default_rng(3)
    sim = 50.0 + np.linspace(0.0, 5.0, 10000)
    meas = sim + 2.0 + rng.normal(0.0, 0.1, sim.size)
    s = offset_stats("T", meas, sim)
    assert s.mean == pytest.approx(2.0, abs=0.01)
    assert s.rms == pytest.approx(math.sqrt(2.0 ** 2 + 0.1 ** 2), abs=0.01)
    assert s.noise == pytest.approx(0.1, rel=0.05)
    assert s.noise_ratio == pytest.approx(20.0, rel=0.05)


def test_reach_by_hand():
    from trackingbox.analysis.offsets import reach

    # gain 2 K per unit, start 10 in [9, 12]: offset +5 K needs +2.5, 2 are left upward -> moves 4 K
    assert reach(2.0, 5.0, 10.0, 9.0, 12.0) == pytest.approx((4.0, 0.8))
    # offset -5 K needs -2.5, only 1 left downward -> moves 2 K
    assert reach(2.0, -5.0, 10.0, 9.0, 12.0) == pytest.approx((2.0, 0.4))
    # a negative gain reverses the direction: -5 K needs +2.5
    assert reach(-2.0, -5.0, 10.0, 9.0, 12.0) == pytest.approx((4.0, 0.8))
    # the valve case: 0.1 of range left downward at 5.93e-4 kg/s per unit, offset -1.34e-3 kg/s
    moves, frac = reach(5.93e-4, -1.34e-3, 1.0, 0.9, 1.1)
    assert moves == pytest.approx(5.93e-5) and frac == pytest.approx(5.93e-5 / 1.34e-3)


def test_predict_tracking_by_hand():
    from trackingbox.analysis.offsets import predict_tracking

    n = 200
    # one loop, constant residual 1, gain 2, instant loop: the move 0.5 is clipped to 0.25,
    # leaving 1 - 2 * 0.25 = 0.5 of the error; the parameter sits at its bound all the time
    p = predict_tracking([[2.0]], [1e-9], np.ones((1, n)), [-1.0], [0.25], 10.0)
    assert p.ratio[0] == pytest.approx(0.5) and p.at_bound[0] == pytest.approx(1.0)
    assert p.need[0] == pytest.approx(2.0)
    # two coupled loops, G = [[1, 0.5], [0, 1]], residuals [1, 1]: moves G^-1 r = [0.5, 1] close both
    p = predict_tracking([[1.0, 0.5], [0.0, 1.0]], [1e-9, 1e-9], np.ones((2, n)), [-2.0, -2.0], [2.0, 2.0], 10.0)
    assert np.allclose(p.ratio, 0.0, atol=1e-12) and np.allclose(p.need, [0.25, 0.5])
    # an error alternating +-1 every sample is far faster than a 1000 s loop: nothing is removed
    alt = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)[None, :]
    p = predict_tracking([[1.0]], [1000.0], alt, [-5.0], [5.0], 10.0)
    assert p.ratio[0] == pytest.approx(1.0, abs=0.02)


def _residuals(rows, n=400, dt=10.0):
    from trackingbox.analysis.offsets import Residuals

    names = tuple(rows)
    meas = np.array([rows[k] for k in names])
    return Residuals(names, dt * np.arange(n), meas, np.zeros_like(meas), dt)


def test_data_checks_leave_out_noise_and_unreachable_offsets():
    from trackingbox.analysis.pairing import DataChecks

    rng = np.random.default_rng(0)
    n = 400
    # y1: offset 0.5 (noise 0.01), a moves it 1 per unit with 1 left upward -> reach 2, paired
    # y2: offset 3, b moves it 1 per unit with 1 left -> reach 1/3 < 0.5, left out
    # y3: pure noise (sigma 0.01) -> nothing to track
    res = _residuals({"y1": 0.5 + rng.normal(0, 0.01, n), "y2": 3.0 + rng.normal(0, 0.01, n),
                      "y3": rng.normal(0, 0.01, n)}, n)
    G = [[1.0, 0.0], [0.0, 1.0], [0.3, 0.3]]
    p = choose_pairs(G, ["y1", "y2", "y3"], ["a", "b"], time_constants=[[10.0, 10.0]] * 3,
                     residuals=res, bounds=[(0.0, -1.0, 1.0), (0.0, -1.0, 1.0)], checks=DataChecks())
    assert _pairs(p) == {"y1": "a"}
    assert "noise" in _reason(p, "y3")
    why = _reason(p, "y2")
    assert "moves y2 by 1 toward the measurement, the offset is 3" in why
    assert p.reach[1, 1] == pytest.approx(1 / 3, rel=0.01)
    # instant-ish loop on a constant offset: what is left is the noise, 0.01 of 0.5
    assert p.pairs[0].predicted_ratio < 0.1 and p.pairs[0].at_bound == 0.0
    assert [o.variable for o in p.offsets] == ["y1", "y2", "y3"]
    assert p.offsets[1].mean == pytest.approx(3.0, abs=0.01)
    # the same case without data pairs y2 with b as well
    assert _pairs(choose_pairs(G, ["y1", "y2", "y3"], ["a", "b"])) == {"y1": "a", "y2": "b"}


def test_data_checks_reject_a_pair_the_loop_cannot_follow():
    from trackingbox.analysis.pairing import DataChecks

    n = 400
    # y1 has a mean offset of 1 (reachable) plus a +-2 error alternating every sample: a 600 s
    # loop removes the mean only, leaving sqrt(4 / 5) = 89 % of the RMS error
    alt = np.where(np.arange(n) % 2 == 0, 2.0, -2.0)
    res = _residuals({"y1": 1.0 + alt, "y2": np.full(n, 0.5) + 0.01 * alt}, n)
    p = choose_pairs([[1.0, 0.0], [0.0, 1.0]], ["y1", "y2"], ["a", "b"], time_constants=[[600.0, 10.0]] * 2,
                     residuals=res, bounds=[(0.0, -2.0, 2.0)] * 2, checks=DataChecks(noise_ratio=0.0))
    assert _pairs(p) == {"y2": "b"}
    assert [(v, q) for v, q, _ in p.rejected] == [("y1", "a")]
    assert "would leave 9" in _reason(p, "y1")
    assert "rejected" in _reason(p, "a")
    with pytest.raises(AnalysisError, match="bounds"):
        choose_pairs([[1.0]], ["y1"], ["a"], residuals=res.subset(["y1"]))
