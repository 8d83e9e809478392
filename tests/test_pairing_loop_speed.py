"""Loop speed per pair (``[pairing] closed_loop_min``): each pair gets the slowest loop its own error allows.

The expectation is the textbook frequency response of a first-order loop, not the code's
own filter: a loop of time constant tau tracking a sinusoid of angular frequency w leaves
``|1 - 1/(1 + i w tau)| = w tau / sqrt(1 + (w tau)^2)`` of its amplitude, so the RMS ratio
tracked/untracked of a pure sinusoid is that number once the start-up has decayed. The loops
tried are 4 h / sqrt(2)^k, written out by hand below.
"""
from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest

from trackingbox.analysis.offsets import Residuals
from trackingbox.analysis.pairing import DataChecks, choose_pairs, loop_ladder

DT = 10.0
SLOWEST = 4 * 3600.0
#: 4 h, 2.83 h, 2 h, 1.41 h, 1 h, 42 min, 30 min, 21 min, 15 min
RUNGS = (14400.0, 10182.3, 7200.0, 5091.2, 3600.0, 2545.6, 1800.0, 1272.8, 900.0)
PERIOD = 20 * 3600.0   # y1's error: a sinusoid of 20 h (a fouling cycle the loop must follow)


def _frequency_response(tau: float) -> float:
    wt = 2 * math.pi / PERIOD * tau
    return wt / math.sqrt(1 + wt * wt)


def _case() -> dict:
    n = int(4 * 86400 / DT)
    t = DT * np.arange(n)
    rng = np.random.default_rng(3)
    y1 = np.sin(2 * np.pi * t / PERIOD)                  # what a loop must follow
    y2 = 1.0 + rng.normal(0.0, 1e-3, n)                  # a constant offset: any loop closes it
    res = Residuals(("y1", "y2"), t, np.array([y1, y2]), np.zeros((2, n)), DT)
    return dict(time_constants=[[5.0, 5.0]] * 2, residuals=res, bounds=[(0.0, -10.0, 10.0)] * 2)


def test_the_ladder_halves_the_loop_every_two_steps():
    assert loop_ladder(SLOWEST, 900.0) == pytest.approx(RUNGS, abs=0.1)
    with pytest.raises(Exception, match="closed_loop"):
        DataChecks(closed_loop=3600.0, closed_loop_min=7200.0)   # the fastest must not be slower
    with pytest.raises(Exception, match="closed_loop"):
        DataChecks(closed_loop_min=900.0)                        # and needs a closed loop to start from


def test_each_pair_gets_the_slowest_loop_its_own_error_allows():
    # by the frequency response: the 1 h loop leaves 30 % of y1's sinusoid (limit 25 %), the 42 min loop 22 %
    # (the discrete loop acts half a sample late: tau + 5 s)
    assert _frequency_response(3600.0 + DT / 2) > 0.29 and _frequency_response(2545.6 + DT / 2) < 0.22
    G = [[1.0, 0.0], [0.0, 1.0]]
    one = choose_pairs(G, ["y1", "y2"], ["a", "b"], checks=DataChecks(closed_loop=SLOWEST), **_case())
    # one loop speed for all (4 h): y1 keeps 70 % of its error and is refused; y2 is tracked
    assert [(p.variable, p.parameter) for p in one.pairs] == [("y2", "b")]
    assert one.pairs[0].closed_loop == SLOWEST
    assert "loops of 14400 s" in dict(one.left_out)["y1"]

    own = choose_pairs(G, ["y1", "y2"], ["a", "b"], checks=DataChecks(closed_loop=SLOWEST, closed_loop_min=900.0),
                       **_case())
    got = {p.variable: p for p in own.pairs}
    assert set(got) == {"y1", "y2"}
    assert got["y1"].closed_loop == pytest.approx(2545.6, abs=0.1)   # the slowest rung under 25 %
    assert got["y2"].closed_loop == SLOWEST                          # unchanged: its error allows the slowest
    assert got["y1"].predicted_ratio == pytest.approx(_frequency_response(2545.6 + DT / 2), rel=0.03)
    assert not own.rejected   # speeding a loop up is not a refusal

    # the fastest loop allowed does not follow it: refused, and the reason says with which loop
    slow = choose_pairs(G, ["y1", "y2"], ["a", "b"],
                        checks=DataChecks(closed_loop=SLOWEST, closed_loop_min=3600.0), **_case())
    assert [p.variable for p in slow.pairs] == ["y2"]
    why = dict(slow.left_out)["y1"]
    assert "its own loop of 3600 s, the fastest allowed" in why
    assert re.search(r"leave (29|30) % of its untracked RMS error", why)   # 0.300 by the frequency response


def test_spec_pairs_tunes_each_pair_for_its_own_loop(tmp_path):
    from trackingbox.analysis.pair_stage import PairSettings, spec_pairs
    from trackingbox.spec import PairingSettings, dump_spec, loads_spec

    G = [[1.0, 0.0], [0.0, 1.0]]
    own = choose_pairs(G, ["y1", "y2"], ["a", "b"], checks=DataChecks(closed_loop=SLOWEST, closed_loop_min=900.0),
                       **_case())
    result = SimpleNamespace(pairing=own, step_settings=SimpleNamespace(interval=DT), settings=PairSettings())
    spec = SimpleNamespace(pairs=(), pairing=PairingSettings(closed_loop=SLOWEST, closed_loop_min=900.0))
    lam = {p.variable: p.lambda_ for p in spec_pairs(spec, result)}
    assert lam == {"y1": pytest.approx(2545.6 / 5.0, rel=1e-4), "y2": pytest.approx(SLOWEST / 5.0)}

    text = ('twin = "twin.fmu"\nmeasurements = "m.csv"\nsample_time = 10.0\n[inputs]\n"u" = "u_in"\n'
            '[outputs]\n"y" = "y_out"\n[[parameters]]\nname = "k"\nstart = 1.0\nmin = 0.5\nmax = 2.0\n')
    loaded = loads_spec(text + "[pairing]\nclosed_loop = 7200.0\nclosed_loop_min = 1800.0\n", tmp_path / "s.toml",
                        check_files=False)
    assert (loaded.pairing.closed_loop, loaded.pairing.closed_loop_min) == (7200.0, 1800.0)
    assert loads_spec(dump_spec(loaded), tmp_path / "s.toml", check_files=False).pairing == loaded.pairing
    with pytest.raises(Exception, match=r"'closed_loop_min' in \[pairing\] \(1800 s\) needs a 'closed_loop'"):
        loads_spec(text + "[pairing]\nclosed_loop_min = 1800.0\n", tmp_path / "s.toml", check_files=False)
