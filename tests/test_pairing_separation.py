"""Pairing's separation check: a paired parameter must be told apart from the candidates left unpaired.

Expectations are solved by hand: the steady state of integrating loops on a linear model
(``S_pp dp + S_pu du = 0``), worked out below for each example.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from trackingbox.analysis.offsets import Residuals
from trackingbox.analysis.pairing import DataChecks, choose_pairs, leakage
from trackingbox.errors import AnalysisError


def test_leakage_is_the_steady_state_of_the_paired_loops():
    # y1 = 2a + b + c, y2 = b + 0.5c, y3 = 0.1a + 0.2b + 3c; y1 paired with a, y2 with b, c unpaired.
    # c moves by 1: y2's loop holds y2 with b = -0.5; y1's loop holds y1 with 2a + b + 1 = 0, a = -0.25.
    S = [[2.0, 1.0, 1.0], [0.0, 1.0, 0.5], [0.1, 0.2, 3.0]]
    L = leakage(S, [0, 1], [0, 1], [2])
    assert L.shape == (2, 1)
    assert L[:, 0] == pytest.approx([0.25, 0.5], abs=1e-12)
    # the same pairs listed the other way round give the same numbers in that order
    assert leakage(S, [1, 0], [1, 0], [2])[:, 0] == pytest.approx([0.5, 0.25], abs=1e-12)
    # y3 paired with c instead: no candidate is unpaired then
    assert leakage(S, [0, 1, 2], [0, 1, 2], []).shape == (3, 0)


@pytest.mark.parametrize("rows, cols, unpaired, message", [
    ([0, 1], [0], [2], "must match one to one"),
    ([0, 0], [0, 1], [2], "must match one to one"),
    ([0], [0], [0], "both paired and unpaired"),
])
def test_leakage_refuses_inconsistent_pairs(rows, cols, unpaired, message):
    with pytest.raises(AnalysisError, match=message):
        leakage([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0]], rows, cols, unpaired)


def test_leakage_refuses_singular_pairs():
    with pytest.raises(AnalysisError, match="singular"):
        leakage([[1.0, 2.0, 1.0], [2.0, 4.0, 0.0]], [0, 1], [0, 1], [2])


def _case() -> dict:
    """Three tags, two parameters; c (think: another effect's fouling) starts at its lower bound.

    Gains:      a     c      offsets (measured - untracked, constant, noise 0.01)
        y1  [ 1.0,  2.5 ]    -0.5
        y2  [ 0.1,  5.0 ]    -1.0
        y3  [ 0.4,  0.1 ]    -0.2

    c can only rise (bounds 0..2 from 0), and every offset needs it lower: no pair with c can close
    its offset (reach 0). y2 is out of a's reach too (its range 2 moves y2 by 0.2 against 1.0).
    So a is the only parameter to pair, with y1 or y3, and c stays unpaired. The relative gains of
    the tall matrix put y1 first for a (0.87 against 0.18 for y3); but on y1 a loop on a moves a by
    S_y1c / S_y1a = 2.5 of its range per range of c (y1 follows c), on y3 by 0.1 / 0.4 = 0.25.
    """
    rng = np.random.default_rng(3)
    n, dt = 400, 10.0
    offsets = {"y1": -0.5, "y2": -1.0, "y3": -0.2}
    names = tuple(offsets)
    meas = np.array([offsets[k] + rng.normal(0.0, 0.01, n) for k in names])
    res = Residuals(names, dt * np.arange(n), meas, np.zeros_like(meas), dt)
    return {"gains": [[1.0, 2.5], [0.1, 5.0], [0.4, 0.1]], "variables": list(names), "parameters": ["a", "c"],
            "time_constants": [[10.0, 10.0]] * 3, "residuals": res,
            "bounds": [(0.0, -2.0, 2.0), (0.0, 0.0, 2.0)]}


def _pairs(p) -> dict[str, str]:
    return {x.variable: x.parameter for x in p.pairs}


def test_separation_moves_a_parameter_to_the_tag_that_tells_it_apart():
    kw = _case()
    gains, variables, parameters = kw.pop("gains"), kw.pop("variables"), kw.pop("parameters")
    off = choose_pairs(gains, variables, parameters, checks=DataChecks(noise_ratio=0.0, max_leak=math.inf), **kw)
    assert _pairs(off) == {"y1": "a"}          # the relative gain alone
    on = choose_pairs(gains, variables, parameters, checks=DataChecks(noise_ratio=0.0, max_leak=0.5), **kw)
    assert _pairs(on) == {"y3": "a"}
    assert [(v, q) for v, q, _ in on.rejected] == [("y1", "a")]
    why = dict(on.left_out)["y1"]
    assert "cannot be told apart from c" in why and "by 2.5 of its own (limit 0.5)" in why
    # without the limit (the default) the relative gain decides
    assert _pairs(choose_pairs(gains, variables, parameters, checks=DataChecks(noise_ratio=0.0), **kw)) == {"y1": "a"}
    # y3's leakage, 0.25, is inside 0.5; a limit below it leaves a unpaired, saying why
    strict = choose_pairs(gains, variables, parameters, checks=DataChecks(noise_ratio=0.0, max_leak=0.2), **kw)
    assert strict.pairs == ()
    assert {(v, q) for v, q, _ in strict.rejected} == {("y1", "a"), ("y3", "a")}
    assert "by 0.25 of its own (limit 0.2)" in dict(strict.left_out)["y3"]
    assert "cannot be told apart from a candidate left unpaired" in dict(strict.left_out)["a"]


def test_separation_limit_must_be_a_non_negative_number_or_inf():
    assert DataChecks(max_leak=math.inf).max_leak == math.inf
    for bad in (-0.1, math.nan, "0.5", True):
        with pytest.raises(AnalysisError, match="max_leak"):
            DataChecks(max_leak=bad)


def _spec(pairing: str):
    from pathlib import Path

    from trackingbox.spec import loads_spec

    text = ('twin = "t.fmu"\nmeasurements = "m.csv"\nsample_time = 10.0\n[inputs]\nu = "u"\n[outputs]\ny = "y"\n'
            f"[pairing]\n{pairing}\n")
    return loads_spec(text, Path("/nonexistent/spec.toml"), check_files=False)


def test_the_spec_asks_for_the_separation_check_and_pair_settings_override_it():
    from trackingbox.analysis.pair_stage import PairSettings, _max_leak
    from trackingbox.spec import dump_spec

    spec = _spec("max_leak = 0.5")
    assert spec.pairing.max_leak == 0.5
    assert "max_leak = 0.5" in dump_spec(spec)
    assert _max_leak(spec, PairSettings()) == 0.5
    assert _max_leak(spec, PairSettings(max_leak=2.0)) == 2.0
    assert _max_leak(_spec("closed_loop = 3600.0"), PairSettings()) == math.inf   # absent: no check


@pytest.mark.parametrize("value", ["-0.5", "0", '"half"'])
def test_a_bad_separation_limit_in_the_spec_is_named(value):
    from trackingbox.errors import SpecError

    with pytest.raises(SpecError, match=r"max_leak"):
        _spec(f"max_leak = {value}")
