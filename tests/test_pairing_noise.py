"""Loop noise (``[pairing] max_jitter``) and tags that identify their unit's parameter at their floor.

The expectations are textbook ones, not the code's: a first-order filter ``1 / (T s + 1)`` (the closed
loop between a tag's error and its parameter's move) passes ``sigma^2 tau / (2 T)`` of the variance of
a stationary noise of variance ``sigma^2`` and integral time scale ``tau`` (for ``T >> tau``); white
noise sampled every ``dt`` has ``tau = dt``, an AR(1) series ``x_k = phi x_k-1 + e_k`` has
``tau = dt (1 + phi) / (1 - phi)``. The loops tried are 4 h / sqrt(2)^k, written out by hand.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from trackingbox.analysis.offsets import Residuals, loop_jitter
from trackingbox.analysis.pairing import DataChecks, choose_pairs

DT = 10.0


def _white(n: int, sigma: float, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, sigma, n)


def _ar1(n: int, sigma: float, phi: float, seed: int = 0) -> np.ndarray:
    e = np.random.default_rng(seed).normal(0.0, sigma * math.sqrt(1 - phi * phi), n)
    return lfilter([1.0], [1.0, -phi], e)


@pytest.mark.parametrize("loop", [1800.0, 3600.0, 7200.0])
def test_loop_jitter_of_white_noise_is_the_filter_formula(loop):
    x = _white(200000, 0.5)
    assert loop_jitter(x, DT, loop) == pytest.approx(0.5 * math.sqrt(DT / (2 * loop)), rel=0.05)


def test_loop_jitter_of_correlated_noise_counts_its_time_scale():
    # phi = 0.8: tau = 10 x 1.8 / 0.2 = 90 s, 3 x the white noise's figure (sqrt 9) for the same sigma
    x = _ar1(300000, 0.5, 0.8)
    expected = 0.5 * math.sqrt(90.0 / (2 * 3600.0))
    assert loop_jitter(x, DT, 3600.0) == pytest.approx(expected, rel=0.15)
    assert loop_jitter(x, DT, 3600.0) > 2.5 * loop_jitter(_white(300000, 0.5), DT, 3600.0)
    # a stoppage (NaN) takes its samples out, not the figure
    y = x.copy()
    y[100000:103000] = np.nan
    assert loop_jitter(y, DT, 3600.0) == pytest.approx(loop_jitter(x, DT, 3600.0), rel=0.05)
    assert math.isnan(loop_jitter(x[:100], DT, 3600.0))   # shorter than the floor's window


SLOWEST = 4 * 3600.0
PERIOD = 20 * 3600.0


def _noisy_case(sigma: float) -> dict:
    """y1: a 20 h sinusoid (amplitude 1) the loop must follow, plus white noise *sigma*; y2: a constant offset.
    Parameter a moves y1 by 1 per unit over its bounds [-1, 1] (range 2)."""
    n = int(4 * 86400 / DT)
    t = DT * np.arange(n)
    y1 = np.sin(2 * np.pi * t / PERIOD) + _white(n, sigma, seed=5)
    y2 = 1.0 + _white(n, 1e-3, seed=6)
    res = Residuals(("y1", "y2"), t, np.array([y1, y2]), np.zeros((2, n)), DT)
    return dict(time_constants=[[5.0, 5.0]] * 2, residuals=res, bounds=[(0.0, -1.0, 1.0), (0.0, -10.0, 10.0)])


def test_max_jitter_slows_a_loop_the_ladder_made_fast_for_its_tag():
    G = [[1.0, 0.0], [0.0, 1.0]]
    sigma = 0.1
    # the noise a loop of T puts into a, in fractions of its range 2: sigma sqrt(dt / 2T) / 2
    jit = {T: sigma * math.sqrt(DT / (2 * T)) / 2 for T in (2545.6, 3600.0, 5091.2, 7200.0)}
    limit = 0.0017
    assert jit[3600.0] > 1.05 * limit and jit[5091.2] < 0.95 * limit   # the quiet rung is 5091 s
    free = choose_pairs(G, ["y1", "y2"], ["a", "b"],
                        checks=DataChecks(closed_loop=SLOWEST, closed_loop_min=900.0), **_noisy_case(sigma))
    got = {p.variable: p for p in free.pairs}
    assert got["y1"].closed_loop == pytest.approx(2545.6, abs=0.1)   # the tag's sinusoid asks for 42 min
    quiet = choose_pairs(G, ["y1", "y2"], ["a", "b"],
                         checks=DataChecks(closed_loop=SLOWEST, closed_loop_min=900.0, max_jitter=limit),
                         **_noisy_case(sigma))
    got = {p.variable: p for p in quiet.pairs}
    assert set(got) == {"y1", "y2"}                                  # slowed, not refused
    assert got["y1"].closed_loop == pytest.approx(5091.2, abs=0.1)
    assert got["y2"].closed_loop == SLOWEST                          # its tag is quiet: unchanged
    # the slower loop lags the sinusoid more: its predicted ratio is that loop's (frequency response)
    wt = 2 * math.pi / PERIOD * (5091.2 + DT / 2)
    assert got["y1"].predicted_ratio > wt / math.sqrt(1 + wt * wt) * 0.9 > 0.25
    warning = next(w for w in quiet.warnings if "slowed" in w)
    assert "y1/a: loop slowed from 2546 s to 5091 s" in warning and "limit 0.0017" in warning


def test_max_jitter_is_checked_and_round_trips_through_the_spec(tmp_path):
    from trackingbox.errors import AnalysisError
    from trackingbox.analysis.pair_stage import PairSettings, _max_jitter
    from trackingbox.spec import dump_spec, loads_spec

    with pytest.raises(AnalysisError, match="max_jitter"):
        DataChecks(closed_loop=3600.0, max_jitter=0.0)
    text = ('twin = "twin.fmu"\nmeasurements = "m.csv"\nsample_time = 10.0\n[inputs]\n"u" = "u_in"\n'
            '[outputs]\n"y" = "y_out"\n[[parameters]]\nname = "k"\nstart = 1.0\nmin = 0.5\nmax = 2.0\n')
    spec = loads_spec(text + "[pairing]\nclosed_loop = 7200.0\nmax_jitter = 0.02\n", tmp_path / "s.toml",
                      check_files=False)
    assert spec.pairing.max_jitter == 0.02
    assert loads_spec(dump_spec(spec), tmp_path / "s.toml", check_files=False).pairing == spec.pairing
    assert _max_jitter(spec, PairSettings()) == 0.02
    assert _max_jitter(spec, PairSettings(max_jitter=0.05)) == 0.05   # the command line wins
    assert _max_jitter(loads_spec(text, tmp_path / "s.toml", check_files=False), PairSettings()) == math.inf
    with pytest.raises(Exception, match="max_jitter"):
        loads_spec(text + "[pairing]\nmax_jitter = -1\n", tmp_path / "s.toml", check_files=False)


def _chain_at_floor(p2_gain: float) -> dict:
    """Two effects of a chain: P1 = Rf1 + 2 Rf2 (effect 1's steam chest sees effect 2's fouling), P2 = g Rf2.
    Rf2 = 0.017 / g so far: P2's offset 0.017 is under twice its noise 0.01 (its floor about half its RMS
    error), P1 shows Rf1 = 0.5 plus Rf2's share."""
    rng = np.random.default_rng(11)
    n = 2000
    rf2 = 0.017 / p2_gain
    meas = np.array([0.5 + 2 * rf2 + rng.normal(0.0, 0.01, n), 0.017 + rng.normal(0.0, 0.01, n)])
    res = Residuals(("P1", "P2"), DT * np.arange(n), meas, np.zeros_like(meas), DT)
    return dict(gains=[[1.0, 2.0], [0.0, p2_gain]], variables=["P1", "P2"],
                parameters=["effect[1].Rf", "effect[2].Rf"], residuals=res,
                bounds=[(0.0, 0.0, 1.0), (0.0, 0.0, 1.0)], time_constants=[[10.0, 10.0]] * 2,
                checks=DataChecks(closed_loop=600.0, max_leak=0.5), units=([1, 2], [1, 2]))


def test_a_tag_at_its_floor_still_carries_the_parameter_it_identifies(monkeypatch):
    # gain 1: a tenth of Rf2's range moves P2 by 0.1, ten times its floor (0.01): it identifies Rf2, so it
    # stays a candidate for it (and for it alone), and both effects pair; the block is triangular
    p = choose_pairs(**_chain_at_floor(1.0))
    assert {x.variable: x.parameter for x in p.pairs} == {"P1": "effect[1].Rf", "P2": "effect[2].Rf"}
    # gain 0.3: a tenth moves it by 0.03, three times its floor (under 5): left out at its floor, effect 2
    # stays unpaired, and the separation check (as before) refuses P1 as well: Rf2 leaks into Rf1 by 2 per
    # range (P1 = Rf1 + 2 Rf2), and P2's RMS error (0.0197) bounds Rf2's move only to 0.0197 / 0.3 = 0.066,
    # weight 0.066 / 0.2 (SEPARATION_MOVE): 2 x 0.33 = 0.66 > 0.5
    q = choose_pairs(**_chain_at_floor(0.3))
    assert q.pairs == ()
    why = dict(q.left_out)
    assert "noise floor" in why["P2"]
    assert "cannot be told apart from effect[2].Rf" in why["effect[1].Rf"]
    # the threshold is what decides: asking for 11 x the floor, the 10 x of gain 1 no longer identifies Rf2
    import trackingbox.analysis.data_checks as data_checks  # where the data checks read it

    monkeypatch.setattr(data_checks, "IDENTIFY_FLOOR", 11.0)
    r = choose_pairs(**_chain_at_floor(1.0))
    assert "P2" not in {x.variable for x in r.pairs} and "noise floor" in dict(r.left_out)["P2"]
