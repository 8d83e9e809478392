"""Diagnosis engine: residual description, screening, judging, the stage and the command.

Unit tests use synthetic residuals of known structure (offset, drift, lag, noise
sigma) and check the answer against the construction. The end-to-end tests run
the heat-exchanger bench: the plain case (verdict ``none``) and the same case
with a sensor bias added to one tag's column by the test (the bias added is the
independent truth).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from trackingbox.diagnose import residuals as rs
from trackingbox.errors import SpecError
from trackingbox.spec import load_spec

# --------------------------------------------------------------------------- spec [[balances]]

BASE = """\
twin = "twin.fmu"
measurements = "m.csv"
sample_time = 10.0

[inputs]
"FI-101" = "mHot_flow"

[outputs]
"TI-102" = "ThOut"
"""


def _case(tmp_path, extra):
    (tmp_path / "twin.fmu").write_bytes(b"PK\x05\x06" + b"\0" * 18)
    (tmp_path / "m.csv").write_text("time,FI-101,FI-102,TI-102\n0,1.0,1.0,60.0\n")
    path = tmp_path / "spec.toml"
    path.write_text(BASE + extra)
    return path


def test_balance_table_read(tmp_path):
    spec = load_spec(_case(tmp_path, '\n[[balances]]\nname = "hot side"\n'
                                     'terms = { "FI-101" = 1.0, "FI-102" = -1.0 }\ntolerance = 0.01\n'))
    (b,) = spec.balances
    assert (b.name, b.terms, b.tolerance) == ("hot side", {"FI-101": 1.0, "FI-102": -1.0}, 0.01)


def test_balance_errors_name_the_entry_and_suggest(tmp_path):
    text = ('\n[[balances]]\nname = "a"\nterm = 1\nterms = { "FI-101" = 1.0, "FI-10" = 0 }\n'
            '\n[[balances]]\nname = "b"\nterms = { "FI-101" = 1.0 }\n')
    with pytest.raises(SpecError) as info:
        load_spec(_case(tmp_path, text))
    msg = str(info.value)
    assert "unknown key 'term' in [[balances]] #1 (did you mean 'terms'?)" in msg
    assert "factor of tag 'FI-10' in [[balances]] #1 terms must be a nonzero number" in msg
    assert "[[balances]] #2 terms need at least two tags" in msg


def test_balance_tag_must_be_a_column(tmp_path):
    text = '\n[[balances]]\nname = "a"\nterms = { "FI-101" = 1.0, "FI-103" = -1.0 }\n'
    with pytest.raises(SpecError, match=r"tag 'FI-103' is not a column of m.csv \(did you mean"):
        load_spec(_case(tmp_path, text))


def test_balance_survives_dump_and_reload(tmp_path):
    from trackingbox.spec import dump_spec, loads_spec

    spec = load_spec(_case(tmp_path, '\n[[balances]]\nname = "hot side"\nterms = { "FI-101" = 1.0, "FI-102" = -2.0 }\n'))
    assert loads_spec(dump_spec(spec), spec.path) == spec


# --------------------------------------------------------------------------- residual description


def test_noise_sigma_of_known_white_noise_on_a_moving_signal():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 8 * 3600.0, 10.0)
    # smooth moves, a step and a ramp: the second difference must not take them for noise
    signal = 60.0 + 3.0 * np.sin(t / 1800.0) + 2.0 * (t > 10000) + np.clip((t - 20000) / 600.0, 0, 1.5)
    for sigma in (0.05, 0.2):
        est = rs.noise_sigma(signal + rng.normal(0.0, sigma, t.size))
        assert abs(est - sigma) < 0.06 * sigma


def test_offset_trend_and_lag_recovered_from_a_synthetic_residual():
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 4 * 3600.0, 10.0)
    y = 50.0 + 5.0 * np.sin(t / 900.0)                       # simulated output
    dy = 5.0 / 900.0 * np.cos(t / 900.0)
    sigma = 0.05
    noise = rng.normal(0.0, sigma, t.size)
    # offset 0.3 and trend 0.1 per hour, no lag
    r = 0.3 + 0.1 * (t - t.mean()) / 3600.0 + noise
    res = rs.characterise("TI", t, r, sigma, simulated=y)
    assert abs(res.offset - 0.3) < 3 * sigma / math.sqrt(t.size)
    assert abs(res.trend - 0.1) < 0.01
    assert res.significant
    # a first-order lag of 60 s: measured ~ y - 60 dy/dt, residual = -60 dy/dt
    res = rs.characterise("TI", t, -60.0 * dy + noise, sigma, simulated=y)
    assert abs(res.lag_seconds - 60.0) < 3.0
    assert res.lag_correlation > 0.9
    # the noise alone: not significant, white
    res = rs.characterise("TI", t, noise, sigma, simulated=y)
    assert not res.significant and abs(res.whiteness) < 0.1 and res.periods == ()


def test_dependence_on_an_input_and_significant_period():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 3600.0 * 6, 10.0)
    u = np.where(t < 3 * 3600, 1.0, 1.4) + rng.normal(0.0, 0.01, t.size)
    w = rng.normal(0.0, 1.0, t.size)
    sigma = 0.1
    # residual = 0.5 K per unit of u above 1: only the second half has a gap
    r = 0.5 * (u - 1.0) + rng.normal(0.0, sigma, t.size)
    res = rs.characterise("TI", t, r, sigma, inputs={"FI": u, "other": w}, blocks=6)
    # regression coefficient per input standard deviation: 0.5 * std(u)
    assert abs(res.conditions["FI"] - 0.5 * np.std(u)) < 0.01
    assert abs(res.conditions["other"]) < 0.01
    # explained share = signal variance / (signal variance + noise variance)
    explained = (0.5 * np.std(u)) ** 2
    assert abs(res.conditions_r2 - explained / (explained + sigma ** 2)) < 0.05
    # the last three of six hour-blocks carry 0.2 K = 2 sigma: one merged period from 3 h
    assert res.periods == ((3 * 3600.0, t[-1] + 10.0),)
