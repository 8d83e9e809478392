"""Pairing's noise floor of exception-reported tags and its prediction with slow closed loops.

Expectations are computed independently: the floor from the known truth of a synthetic
historian series (sample-and-hold of dead-band records, written out here), the prediction
from the closed form of a first-order loop on a constant offset with white noise.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from trackingbox.analysis.offsets import (Residuals, held_fraction, noise_floor, noise_sigma, offset_stats,
                                          predict_tracking)
from trackingbox.analysis.pairing import DataChecks, choose_pairs


def _historian(truth: np.ndarray, sigma: float, band: float, heartbeat: int, rng: np.random.Generator) -> np.ndarray:
    """Dead-band (exception) reporting of ``truth + noise`` scanned every sample, held between records."""
    noisy = truth + rng.normal(0.0, sigma, truth.size)
    held = np.empty_like(noisy)
    last, since = noisy[0], 0
    for k, x in enumerate(noisy):
        if abs(x - last) > band or since >= heartbeat:
            last, since = x, 0
        since += 1
        held[k] = last
    return held


@pytest.mark.parametrize(("sigma", "band", "low"), [(0.2, 0.2, 0.85), (200.0, 300.0, 0.85), (0.05, 0.3, 0.6)])
def test_noise_floor_of_a_held_series_matches_its_distance_from_the_truth(sigma, band, low):
    # noise near the dead band (the evaporator's temperatures and pressures): within 15 %; a dead band
    # far above the noise (its flows): the held value lags a moving truth by one sign for as long as it
    # moves one way, slower than the 30 min average, so the estimate is a lower bound (0.74 here)
    rng = np.random.default_rng(11)
    n, dt = 30000, 10.0
    t = np.arange(n) * dt
    scale = band / 0.2
    truth = scale * (3.0 * np.sin(2 * np.pi * t / 86400.0) + 0.5 * np.sin(2 * np.pi * t / 20000.0))
    held = _historian(truth, sigma, band, heartbeat=60, rng=rng)
    expected = float(np.sqrt(np.mean((held - truth) ** 2)))   # what no loop following the truth removes
    assert held_fraction(held) > 0.5
    assert noise_sigma(held) == pytest.approx(0.0, abs=1e-3 * band)   # the difference-based estimate fails
    # measured - untracked twin: the twin follows the truth's movement but has an offset
    simulated = truth - 2.0 * scale
    assert low * expected <= noise_floor(held - simulated, dt) <= 1.15 * expected
    s = offset_stats("T", held, simulated, dt)
    assert s.noise == noise_floor(held - simulated, dt)
    assert s.rms == pytest.approx(math.sqrt(4.0 * scale ** 2 + expected ** 2), rel=0.02)
    # without the grid interval (or for a dense noisy series) the difference-based estimate stays
    assert offset_stats("T", held, simulated).noise == noise_sigma(held)


def test_noise_floor_skips_windows_with_gaps_and_needs_a_full_window():
    rng = np.random.default_rng(2)
    x = rng.normal(0.0, 0.5, 5000)
    x[1000:1500] = 1e6            # a stretch that must not count ...
    x[999] = x[1500] = np.nan     # ... is cut off by NaNs, so no valid window reaches it
    y = x.copy()
    y[1000:1500] = np.nan
    assert noise_floor(y, 10.0) == pytest.approx(0.5, rel=0.05)
    assert math.isnan(noise_floor(y[:100], 10.0))   # shorter than one 30 min window


def test_prediction_with_a_slow_closed_loop_keeps_the_noise_and_the_transient():
    # constant offset c plus white noise sigma; a first-order loop a = exp(-dt / tau) leaves
    # x_k - y_k: the noise part has variance a^2 (sigma^2 + sigma^2 (1 - a) / (1 + a)), the offset
    # part decays as c a^(k+1) (sum of squares c^2 a^2 / (1 - a^2))
    rng = np.random.default_rng(5)
    n, dt, c, sigma = 26000, 10.0, 1.0, 0.5
    r = c + rng.normal(0.0, sigma, n)
    for tau in (10.0, 10800.0):
        a = math.exp(-dt / tau)
        var = a * a * (sigma ** 2 + sigma ** 2 * (1 - a) / (1 + a)) + c * c * a * a / (1 - a * a) / n
        expected = math.sqrt(var / (c * c + sigma ** 2))
        p = predict_tracking([[1.0]], [tau], r[None, :], [-10.0], [10.0], dt)
        assert p.ratio[0] == pytest.approx(expected, rel=0.05)
    assert expected > 0.25   # the 3 h loop: the noise stays (0.45 of the error) and the start-up transient
    # judged after 3 closed-loop time constants the transient is down to exp(-3) of the offset at most
    settled = predict_tracking([[1.0]], [tau], r[None, :], [-10.0], [10.0], dt, settle=3 * tau)
    m = n - int(3 * tau / dt)
    tail = c * c * a ** (2 * (n - m + 1)) / (1 - a * a) / m
    noise_only = math.sqrt((a * a * (sigma ** 2 + sigma ** 2 * (1 - a) / (1 + a)) + tail) / (c * c + sigma ** 2))
    assert settled.ratio[0] == pytest.approx(noise_only, rel=0.05)
    assert settled.ratio[0] < expected


def test_closed_loop_check_rejects_a_tag_at_its_floor_and_says_why():
    rng = np.random.default_rng(8)
    n, dt = 20000, 10.0
    # y1: offset 0.3 with noise 0.2 (noise 0.55 of its RMS); y2: offset 1 with noise 0.01
    res = Residuals(("y1", "y2"), dt * np.arange(n),
                    np.array([0.3 + rng.normal(0, 0.2, n), 1.0 + rng.normal(0, 0.01, n)]), np.zeros((2, n)), dt)
    kw = dict(time_constants=[[5.0, 5.0]] * 2, residuals=res, bounds=[(0.0, -5.0, 5.0)] * 2)
    G = [[1.0, 0.0], [0.0, 1.0]]
    fast = choose_pairs(G, ["y1", "y2"], ["a", "b"], checks=DataChecks(noise_ratio=0.0), **kw)
    assert {p.variable for p in fast.pairs} == {"y1", "y2"}     # a 5 s loop "tracks" the noise
    slow = choose_pairs(G, ["y1", "y2"], ["a", "b"], checks=DataChecks(noise_ratio=0.0, closed_loop=10800.0), **kw)
    assert {(p.variable, p.parameter) for p in slow.pairs} == {("y2", "b")}
    why = dict(slow.left_out)["y1"]
    # its floor 0.2 is 0.2 / sqrt(0.3^2 + 0.2^2) = 55 % of its RMS error: no loop gets it under 30 %
    assert re.search(r"noise floor 0\.2\d* .* is 5[56] % of its untracked RMS error", why) and "loops of 10800 s" in why
    assert slow.pairs[0].predicted_ratio < 0.25
    with pytest.raises(Exception, match="closed_loop"):
        DataChecks(closed_loop=-1.0)


def test_closed_loop_check_judges_the_error_above_the_floor():
    rng = np.random.default_rng(9)
    n, dt = 20000, 10.0
    # y1: offset 0.5, noise 0.15: floor 0.29 of its RMS (under 30 %), so a 3 h loop leaves at least
    # that of the whole error (above the 25 % limit) but almost nothing of the error above the floor
    res = Residuals(("y1",), dt * np.arange(n), np.array([0.5 + rng.normal(0, 0.15, n)]), np.zeros((1, n)), dt)
    checks = DataChecks(closed_loop=10800.0)
    p = choose_pairs([[1.0]], ["y1"], ["a"], time_constants=[[5.0]], residuals=res, bounds=[(0.0, -5.0, 5.0)],
                     checks=checks)
    assert [(x.variable, x.parameter) for x in p.pairs] == [("y1", "a")]
    f = 0.15 / math.hypot(0.5, 0.15)
    assert f < 0.3 < p.pairs[0].predicted_ratio + 0.05 and p.pairs[0].predicted_ratio > f
    # the same tag with a 2 h lag of the offset it cannot follow: a step the loop meets only after
    # 9 h of the window's 55 h, so the error above the floor stays and the pair is refused
    late = np.where(np.arange(n) < n - 2000, 0.0, 2.0) + 0.5 + rng.normal(0, 0.15, n)
    res2 = Residuals(("y1",), dt * np.arange(n), late[None, :], np.zeros((1, n)), dt)
    q = choose_pairs([[1.0]], ["y1"], ["a"], time_constants=[[5.0]], residuals=res2, bounds=[(0.0, -5.0, 5.0)],
                     checks=checks)
    assert q.pairs == () and "above its noise floor" in dict(q.left_out)["y1"]


def test_spec_pairing_closed_loop_loads_dumps_and_is_checked(tmp_path):
    from trackingbox.errors import SpecError
    from trackingbox.spec import dump_spec, loads_spec

    text = ('twin = "twin.fmu"\nmeasurements = "m.csv"\nsample_time = 10.0\n[inputs]\n"u" = "u_in"\n'
            '[outputs]\n"y" = "y_out"\n[[parameters]]\nname = "k"\nstart = 1.0\nmin = 0.5\nmax = 2.0\n')
    spec = loads_spec(text + "[pairing]\nclosed_loop = 10800.0\n", tmp_path / "spec.toml", check_files=False)
    assert spec.pairing.closed_loop == 10800.0
    again = loads_spec(dump_spec(spec), tmp_path / "spec.toml", check_files=False)
    assert again.pairing == spec.pairing
    assert loads_spec(text, tmp_path / "spec.toml", check_files=False).pairing.closed_loop is None
    with pytest.raises(SpecError, match=r"'closed_loop' in \[pairing\] must be > 0"):
        loads_spec(text + "[pairing]\nclosed_loop = -5.0\n", tmp_path / "spec.toml", check_files=False)


def test_spec_pairs_tunes_a_new_pair_for_the_closed_loop():
    from types import SimpleNamespace

    from trackingbox.analysis.pair_stage import PairSettings, spec_pairs
    from trackingbox.analysis.pairing import Pair, Pairing
    from trackingbox.spec import PairingSettings, PairSpec

    result = SimpleNamespace(pairing=Pairing((Pair("y", "k", 1.0, 2.0, 120.0), Pair("z", "m", 1.0, 3.0, 4e4)), (), ()),
                             step_settings=SimpleNamespace(interval=10.0), settings=PairSettings())
    spec = SimpleNamespace(pairs=(), pairing=PairingSettings(closed_loop=10800.0))
    out = {p.variable: p.lambda_ for p in spec_pairs(spec, result)}
    assert out == {"y": pytest.approx(90.0), "z": 1.0}   # 10800 / 120; a slower step response keeps 1
    plain = SimpleNamespace(pairs=(), pairing=PairingSettings())
    assert {p.lambda_ for p in spec_pairs(plain, result)} == {1.0}
    # the settings override the spec's; an existing pair keeps its tuning
    result.settings = PairSettings(closed_loop=1200.0)
    assert spec_pairs(spec, result)[0].lambda_ == pytest.approx(10.0)
    spec.pairs = (PairSpec(variable="y", parameter="k", gain=1.0, time_constant=100.0, lambda_=3.0),)
    assert spec_pairs(spec, result)[0].lambda_ == 3.0


def test_fix_parameters_moves_estimates_into_fixed(tmp_path):
    from trackingbox.benches.evaporator import fix_parameters
    from trackingbox.errors import SpecError
    from trackingbox.spec import load_spec

    (tmp_path / "twin.fmu").write_bytes(b"")
    (tmp_path / "m.csv").write_text("time,u,y\n0,1,2\n10,1,2\n")
    text = ('twin = "twin.fmu"\nmeasurements = "m.csv"\nsample_time = 10.0\n[inputs]\n"u" = "u_in"\n'
            '[outputs]\n"y" = "y_out"\n[[parameters]]\nname = "k"\nstart = 1.0\nmin = 0.5\nmax = 2.0\n'
            '[[parameters]]\nname = "dBPR"\nstart = 0.0\nmin = -2.0\nmax = 5.0\n[fixed]\n"A" = 3.0\n')
    (tmp_path / "spec.toml").write_text(text)
    spec = fix_parameters(tmp_path / "spec.toml", {"dBPR": 0.94})
    again = load_spec(tmp_path / "spec.toml", check_files=False)
    assert [p.name for p in again.parameters] == ["k"] and again.fixed == {"A": 3.0, "dBPR": 0.94}
    assert spec.fixed == again.fixed
    before = (tmp_path / "spec.toml").read_text()
    with pytest.raises(SpecError, match=r"\['nope'\] are not \[\[parameters\]\] entries"):
        fix_parameters(tmp_path / "spec.toml", {"nope": 1.0})
    assert (tmp_path / "spec.toml").read_text() == before   # nothing half-written


def test_floor_aware_relative_gains_leave_out_the_tags_at_their_floor():
    rng = np.random.default_rng(4)
    n, dt = 20000, 10.0
    # one parameter a, three tags: y1 moves 10 per unit but sits at its floor (offset 0.5, noise 1);
    # y2 and y3 move 1 and 2 per unit with offsets 0.1 and 0.2 (the same move 0.1 of a) and no noise
    res = Residuals(("y1", "y2", "y3"), dt * np.arange(n),
                    np.array([0.5 + rng.normal(0, 1.0, n), np.full(n, 0.1), np.full(n, 0.2)]), np.zeros((3, n)), dt)
    kw = dict(time_constants=[[5.0]] * 3, residuals=res, bounds=[(0.0, -1.0, 1.0)])
    G = [[10.0], [1.0], [2.0]]
    # tall RGA of one column: g_i^2 / sum g^2 = 100/105, 1/105, 4/105: y1 would take the column
    plain = choose_pairs(G, ["y1", "y2", "y3"], ["a"], checks=DataChecks(noise_ratio=0.0), **kw)
    assert plain.rga[:, 0] == pytest.approx([100 / 105, 1 / 105, 4 / 105])
    floor = choose_pairs(G, ["y1", "y2", "y3"], ["a"], checks=DataChecks(closed_loop=10800.0), **kw)
    assert "noise floor" in dict(floor.left_out)["y1"]
    # over y2, y3 alone: 1/5 and 4/5; y3 is paired
    assert math.isnan(floor.rga[0, 0]) and floor.rga[1:, 0] == pytest.approx([0.2, 0.8])
    assert [(p.variable, p.parameter) for p in floor.pairs] == [("y3", "a")]


def test_a_parameter_the_data_checks_refuse_everywhere_names_the_tags_it_could_serve():
    rng = np.random.default_rng(11)
    n, dt = 20000, 10.0
    # y1 needs a to move by 1 (offset 1, gain 1) but a's bounds allow 0.01: it cannot close the offset;
    # y2 and b are an easy pair. a's relative gain with y1 is 1 (identity gains), with y2 0.
    res = Residuals(("y1", "y2"), dt * np.arange(n),
                    np.array([1.0 + rng.normal(0, 0.01, n), 0.5 + rng.normal(0, 0.01, n)]), np.zeros((2, n)), dt)
    p = choose_pairs([[1.0, 0.0], [0.0, 1.0]], ["y1", "y2"], ["a", "b"], time_constants=[[5.0, 5.0]] * 2,
                     residuals=res, bounds=[(0.0, -0.01, 0.01), (0.0, -5.0, 5.0)], checks=DataChecks(noise_ratio=0.0))
    assert [(x.variable, x.parameter) for x in p.pairs] == [("y2", "b")]
    why = dict(p.left_out)
    assert "offset" in why["y1"]
    assert re.search(r"rejected it for every variable it could serve: y1 \(lambda 1\)", why["a"]), why["a"]
    assert "y2" not in why["a"]   # a does not move y2: not one it could serve


def test_floor_aware_pairing_leaves_out_a_parameter_the_trackable_tags_cannot_tell_apart():
    rng = np.random.default_rng(12)
    n, dt = 20000, 10.0
    # y1 sits at its floor (offset 0.3, noise 0.2: 55 % of its RMS) and is the only tag that tells a
    # from b; on y2 and y3 the columns of a (1, 2) and b (2, 4) are parallel: rank 1, whose relative
    # gain array does not exist. b, the stronger column (norm sqrt(20) against sqrt(5)), stays;
    # y2 and y3 have offsets b closes at 0.1 (y2 0.2 = 2 x 0.1, y3 0.4 = 4 x 0.1), without noise
    res = Residuals(("y1", "y2", "y3"), dt * np.arange(n),
                    np.array([0.3 + rng.normal(0, 0.2, n), np.full(n, 0.2), np.full(n, 0.4)]), np.zeros((3, n)), dt)
    G = [[10.0, 0.0], [1.0, 2.0], [2.0, 4.0]]
    p = choose_pairs(G, ["y1", "y2", "y3"], ["a", "b"], time_constants=[[5.0, 5.0]] * 3, residuals=res,
                     bounds=[(0.0, -1.0, 1.0)] * 2, checks=DataChecks(noise_ratio=0.0, closed_loop=10800.0))
    why = dict(p.left_out)
    assert "noise floor" in why["y1"]
    assert "on the tags worth tracking" in why["a"] and "linear combination of those of b" in why["a"]
    assert [x.parameter for x in p.pairs] == ["b"] and p.pairs[0].variable in ("y2", "y3")
