"""Diagnosis engine: residual description, screening, judging, the stage and the command.

Unit tests use synthetic residuals of known structure (offset, drift, lag, noise
sigma) and check the answer against the construction. The end-to-end tests run
the heat-exchanger bench: the plain case (verdict ``none``) and the same case
with a sensor bias added to one tag's column by the test (the bias added is the
independent truth).
"""
from __future__ import annotations

import math
from pathlib import Path

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

    text = '\n[[balances]]\nname = "hot side"\nterms = { "FI-101" = 1.0, "FI-102" = -2.0 }\n'
    spec = load_spec(_case(tmp_path, text))
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


# --------------------------------------------------------------------------- screening transforms

from trackingbox.diagnose import candidates as cd  # noqa: E402
from trackingbox.diagnose import screen as sc  # noqa: E402


def test_first_order_matches_the_analytic_step_response():
    t = np.arange(0.0, 600.0, 10.0)
    u = np.where(t >= 10.0, 1.0, 0.0)          # a ramp from 0 to 1 over the first step, then held
    x = sc.first_order(t, u, 60.0)
    # after the ramp [0, 10] the response is 1 - (tau/h)(1 - exp(-h/tau)) exp(-(t - h)/tau) (hand-solved)
    h, tau = 10.0, 60.0
    expected = 1.0 - (tau / h) * (1.0 - math.exp(-h / tau)) * np.exp(-(t[1:] - h) / tau)
    assert np.allclose(x[1:], expected, atol=1e-12)


def test_sensor_transforms_recover_bias_drift_and_lag():
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 3 * 3600.0, 10.0)
    y = 40.0 + 4.0 * np.sin(t / 700.0) + 2.0 * (t > 5000)
    sigma = 0.05
    e = rng.normal(0.0, sigma, t.size)
    b, after = sc.fit_bias(y + 0.4 + e - y)
    assert abs(b - 0.4) < 3 * sigma / math.sqrt(t.size) and abs(np.std(after) - sigma) < 0.1 * sigma
    (a, c), _ = sc.fit_drift(t, 0.1 + 2e-5 * t + e)
    assert abs(a - 0.1) < 0.01 and abs(c - 2e-5) < 1e-6
    measured = sc.first_order(t, y, 120.0) + e
    tau, after = sc.fit_lag(t, y, measured, bounds=(0.0, 1800.0))
    assert abs(tau - 120.0) < 5.0 and abs(np.std(after) - sigma) < 0.1 * sigma


def _sensor_where(error, sigma=0.05, seed=3):
    """A synthetic null model of one tag "T": simulated = a smooth signal, measured = it + *error*(t) + noise.

    Training is [0, 4 h), validation [4 h, 8 h) (time from the first sample, as in the bench cases).
    """
    from types import SimpleNamespace as NS

    rng = np.random.default_rng(seed)
    windows = []
    for name, lo in (("training", 0.0), ("validation", 4 * 3600.0)):
        t = np.arange(lo, lo + 4 * 3600.0, 10.0)
        sim = 320.0 + 3.0 * np.sin(t / 900.0)
        meas = sim + error(t) + rng.normal(0.0, sigma, t.size)
        windows.append(rs.WindowResiduals(name, t, {"T": meas}, {"T": sim}, {}))
    return NS(training=windows[0], validation=windows[1], tags={"T": None}, noise={"T": sigma},
              jacobian=({}, {}), problem=None, x=None)


def _drift_entry():
    from trackingbox.diagnose.library import load_effects

    return load_effects()["sensor-drift"]


def test_levelling_drift_recovers_its_own_rate_and_levelling():
    # error 5e-5 * t / (1 + 1e-4 t): 5e-5 K/s at the start, half of its 0.5 K limit after 10 000 s
    where = _sensor_where(lambda t: 5e-5 * t / (1.0 + 1e-4 * t))
    c = sc.screen_sensor(_drift_entry(), "T", where, relinearise=False)
    assert c.values["d"] == pytest.approx(5e-5, rel=0.05) and c.values["c"] == pytest.approx(1e-4, rel=0.15)
    assert not c.pinned and c.validation_gain > 0.8
    # a straight drift is the nested form c = 0
    c = sc.screen_sensor(_drift_entry(), "T", _sensor_where(lambda t: 3e-5 * t), relinearise=False)
    assert c.values["d"] == pytest.approx(3e-5, rel=0.02) and c.values["c"] < 2e-6


def test_a_drift_that_levels_off_is_named_a_drift_not_a_bias():
    """The hidden case's form (an exponential from 1 h on, which the template does not have) against bias."""
    from trackingbox.diagnose.library import load_effects

    def error(t):
        return 1.5 * (1.0 - np.exp(-np.maximum(t - 3600.0, 0.0) / 20000.0))

    where = _sensor_where(error, sigma=0.1)
    where.validation_tags = {"T": _samples(1440)}
    where.significant = ["T"]
    bias = sc.screen_sensor(load_effects()["sensor-bias"], "T", where, relinearise=False)
    drift = sc.screen_sensor(_drift_entry(), "T", where, relinearise=False)
    assert drift.delta_bic > bias.delta_bic + 10 and drift.validation_gain > bias.validation_gain
    # the levelled form follows the held-out error: 1.07 K at 8 h; a straight line fitted on training reaches 1.6 K
    after = drift.validation_residual["T"]
    assert abs(np.mean(after[-360:])) < 0.15
    verdict = jd.judge(sc.rank([bias, drift]), where)
    assert verdict.verdict == "effect" and verdict.named.effect == "sensor-drift"
    # a constant bias is named a bias: the drift cannot beat it by the BIC's margin, or its levelling is pinned
    where = _sensor_where(lambda t: 0.8 + 0.0 * t, sigma=0.1)
    where.validation_tags = {"T": _samples(1440)}
    where.significant = ["T"]
    bias = sc.screen_sensor(load_effects()["sensor-bias"], "T", where, relinearise=False)
    drift = sc.screen_sensor(_drift_entry(), "T", where, relinearise=False)
    verdict = jd.judge(sc.rank([bias, drift]), where)
    assert verdict.verdict == "effect" and verdict.named.effect == "sensor-bias"


def _samples(n):
    from types import SimpleNamespace as NS

    return NS(samples=n, periods=())


def test_delta_bic_prefers_a_true_bias_and_refuses_a_spurious_one():
    rng = np.random.default_rng(8)
    e = rng.normal(0.0, 0.1, 2000)
    assert cd.delta_bic({"T": e + 0.1}, {"T": e}, 1) > 10         # one sigma of bias over 2000 samples
    assert cd.delta_bic({"T": e}, {"T": e - e.mean()}, 1) < 0     # fitting the noise's mean costs ln(n)


def test_propagated_input_noise_matches_the_first_order_filter_variance(monkeypatch):
    """A first-order lag sampled every dt, fed a noisy input: the output's spread from the input noise.

    ``y[k+1] = a y[k] + (1 - a) u[k]`` with ``a = exp(-dt / tau)`` passes white input
    noise of variance ``s**2`` as output variance ``s**2 (1 - a) / (1 + a)`` (the
    filter's noise gain, a standard result). That is the spread a second, independent
    draw of the input noise must add to the simulated output.
    """
    from types import SimpleNamespace as NS

    dt, tau, s = 10.0, 60.0, 0.4
    a = math.exp(-dt / tau)

    def lag(problem, window, x, input_tags):
        u = window.inputs["u"]
        y = np.empty_like(u)
        y[0] = u[0]
        for k in range(1, u.size):
            y[k] = a * y[k - 1] + (1.0 - a) * u[k - 1]
        return rs.WindowResiduals(window.name, window.time, window.measured, {"Y": y}, {"u": u})

    monkeypatch.setattr(rs, "window_series", lag)
    rng = np.random.default_rng(11)
    windows = []
    for name in ("training", "validation"):
        t = np.arange(0.0, 20000 * dt, dt)
        u = 3.0 + np.where(t > t[-1] / 2, 1.0, 0.0) + rng.normal(0.0, s, t.size)   # a step and the noise
        windows.append(NS(name=name, time=t, inputs={"u": u, "sp": np.full(t.size, 5.0)},
                          measured={"Y": np.where(t < 600.0, np.nan, 0.0)}, lead=0))
    # dataclasses.replace needs a dataclass: the windows are the estimation's WindowData
    from trackingbox.estimation import WindowData

    windows = [WindowData(w.name, 0.0, float(w.time[-1]), w.time, w.inputs, w.measured) for w in windows]
    series = [lag(None, w, None, {}) for w in windows]
    spread = rs.propagated_noise(None, windows, None, {}, series)
    expected = s * math.sqrt((1.0 - a) / (1.0 + a))
    assert spread["Y"] == pytest.approx(expected, rel=0.05)
    # a noise-free input (a set point) is not perturbed; without any noisy input nothing propagates
    assert rs.input_noise(windows[0])["sp"] == 0.0
    quiet = [WindowData(w.name, w.start, w.stop, w.time, {"u": np.full(w.time.size, 3.0)}, w.measured)
             for w in windows]
    assert rs.propagated_noise(None, quiet, None, {}, [lag(None, w, None, {}) for w in quiet]) == {"Y": 0.0}


def test_validation_gain_counts_the_tags_an_effect_materially_moves():
    """A process effect that closes the gap on one tag and nudges nine others by a tenth of their noise."""
    from types import SimpleNamespace as NS

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 4 * 3600.0, 10.0)
    tags = ["T"] + [f"F{i}" for i in range(9)]
    gap = {"T": 2.0}
    windows, after = [], []
    for name in ("training", "validation"):
        meas = {g: 10.0 + 0.5 * np.sin(t / 900.0) + gap.get(g, 0.0) + rng.normal(0.0, 0.1, t.size) for g in tags}
        sim = {g: 10.0 + 0.5 * np.sin(t / 900.0) for g in tags}
        windows.append(rs.WindowResiduals(name, t, meas, sim, {}))
        # the effect: T's gap closed, every other tag moved by 0.01 (a tenth of its noise)
        after.append({g: meas[g] - sim[g] - (gap["T"] if g == "T" else 0.01) for g in tags})
    where = NS(training=windows[0], validation=windows[1], noise={g: 0.1 for g in tags})
    c = cd.score("heat-loss", "X", "process", "fit", where, 1, after[0], after[1], {})
    assert set(c.tags) == set(tags)                                   # all ten are affected (enter ΔBIC, "worse")
    nb, na = c.nrmse_before["T"], c.nrmse_after["T"]
    assert c.validation_gain == pytest.approx(1.0 - na / nb)          # the gain is T's alone
    assert c.validation_gain > 0.9
    assert c.material == ("T",)                                       # 2.0 = 20 sigma; the 0.01 nudges are not


def test_an_effect_that_moves_a_significant_gap_without_closing_it_is_not_named():
    """Two significant tags; the candidate closes one and reshapes the other without closing it."""
    from types import SimpleNamespace as NS

    where = NS(validation_tags={t: NS(samples=500, periods=()) for t in ("L", "P", "F")},
               significant=["L", "P"], tags={t: NS(periods=((0.0, 600.0),)) for t in ("L", "P")})
    limit = jd.noise_threshold(500)
    # L closed by 1.3 noise variances, P (significant, materially moved) by 0.15: that gap is not its doing
    c = cd.Candidate("level-density", "LT", "process", "fit", delta_bic=137.0, validation_gain=0.16, noise_gain=1.5,
                     tags=("L", "P", "F"), noise_gains={"L": 1.3, "P": 0.15, "F": 0.05}, material=("L", "P"))
    why = jd.objections(c, where)
    assert len(why) == 1 and "P" in why[0] and "does not close it" in why[0] and 0.15 < limit
    verdict = jd.judge([c], where)
    assert verdict.verdict == "unexplained" and set(verdict.unexplained) == {"L", "P"}
    # closing both gaps beyond noise: named
    ok = cd.Candidate("steam-vent", "E", "process", "fit", delta_bic=137.0, validation_gain=0.5, noise_gain=3.0,
                      tags=("L", "P", "F"), noise_gains={"L": 1.3, "P": 1.6, "F": 0.05}, material=("L", "P"))
    assert jd.objections(ok, where) == [] and jd.judge([ok], where).named is ok
    # a significant tag it moves by less than MATERIAL_MOVE sigma is not held to it (a second effect may be
    # behind that gap): the name stands with the gap it closes
    one = cd.Candidate("steam-vent", "E", "process", "fit", delta_bic=137.0, validation_gain=0.5, noise_gain=1.4,
                       tags=("L", "P", "F"), noise_gains={"L": 1.3, "P": 0.05, "F": 0.05}, material=("L",))
    assert jd.objections(one, where) == []


# --------------------------------------------------------------------------- judging (fast)

from trackingbox.diagnose import judge as jd  # noqa: E402


def test_a_candidate_failing_any_check_is_never_named():
    good = cd.Candidate("sensor-bias", "T", "sensor", "screen", delta_bic=50.0, validation_gain=0.5, noise_gain=3.0)
    assert jd.reasons_against(good, 500) == []
    assert jd.reasons_against(cd.Candidate("b", "T", "sensor", "screen", 9.0, 0.5, 3.0), 500)      # ΔBIC <= 10
    assert jd.reasons_against(cd.Candidate("b", "T", "sensor", "screen", 50.0, 0.5, 0.1), 500)     # within noise
    assert jd.reasons_against(cd.Candidate("b", "T", "sensor", "screen", 50.0, -0.1, 3.0), 500)    # NRMSE rises
    assert jd.reasons_against(cd.Candidate("b", "T", "sensor", "screen", 50.0, 0.04, 3.0), 500)    # falls 4 %
    assert jd.reasons_against(cd.Candidate("b", "T", "sensor", "screen", 50.0, 0.5, 3.0, pinned=("tau",)), 500)


# --------------------------------------------------------------------------- end to end on the heat-exchanger bench

HX = "TrackingBox.Benches.HeatExchanger"
#: Bias added to TI-102 (K): ten times the bench's 0.1 K thermometer noise.
BIAS = 1.0


@pytest.fixture(scope="module")
def hx_bench(fmu_cache, tmp_path_factory):
    from trackingbox.benches import make_bench

    return make_bench("heat-exchanger", tmp_path_factory.mktemp("dg-hx") / "case", seed=0, hours=3.0,
                      plant_fmu=fmu_cache(f"{HX}.Plant"), twin_fmu=fmu_cache(f"{HX}.Twin"))


def _copy_case(bench, directory, bias=0.0):
    import shutil

    import pandas as pd

    src = bench.directory
    directory.mkdir()
    for name in ("spec.toml", "twin.fmu"):
        shutil.copy(src / name, directory / name)
    frame = pd.read_csv(src / "measurements.csv")
    frame["TI-102"] = frame["TI-102"] + bias
    frame.to_csv(directory / "measurements.csv", index=False)
    return load_spec(directory / "spec.toml")


SETTINGS = dict(maxiter=4)


@pytest.mark.compile
@pytest.mark.slow
def test_plain_bench_gives_verdict_none(hx_bench, tmp_path):
    from trackingbox.diagnose import DiagnoseSettings, diagnose

    spec = _copy_case(hx_bench, tmp_path / "plain")
    result = diagnose(spec, DiagnoseSettings(**SETTINGS))
    doc = result.to_json()
    assert doc["verdict"] == "none", doc["candidates"]
    assert doc["findings"] == []
    assert not any(w["significant"] for w in doc["where"].values())


@pytest.mark.compile
@pytest.mark.slow
def test_injected_sensor_bias_is_named_on_its_tag(hx_bench, tmp_path, capsys):
    """Through the command: --json is the issue's contract, --report and -o write their files."""
    import json

    from trackingbox.cli import main

    spec = _copy_case(hx_bench, tmp_path / "biased", bias=BIAS)
    code = main(["diagnose", str(spec.path), "--json", "--maxiter", str(SETTINGS["maxiter"]),
                 "--report", str(tmp_path / "report"), "-o", str(tmp_path / "patched")])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) >= {"verdict", "findings", "candidates", "where", "patch", "seconds"}
    assert doc["verdict"] == "effect", doc["candidates"]
    (finding,) = doc["findings"]
    assert (finding["effect"], finding["target"]) == ("sensor-bias", "TI-102")
    # every candidate says why it was not named; the named one says nothing
    entries = {(c["effect"], c["target"]): c["not_named"] for c in doc["candidates"]}
    assert entries.pop(("sensor-bias", "TI-102")) == []
    assert entries and all(isinstance(why, list) and why for why in entries.values()), entries
    # the bias added, within two noise standard deviations of the thermometer (estimated from the data)
    where = doc["where"]["TI-102"]
    assert abs(where["sensor_noise"] - 0.1) < 0.02       # the bench's thermometer noise
    # the inlet thermometers' noise reaches the outlet temperature through the twin: judged on both parts
    assert where["input_noise"] > 0 and where["noise"] == pytest.approx(math.hypot(where["sensor_noise"],
                                                                                   where["input_noise"]))
    noise = where["noise"]
    (value,) = finding["parameters"].values()
    assert abs(value - BIAS) < 2 * noise
    assert finding["delta_bic"] > 10
    before, after = finding["validation"]["nrmse_before"]["TI-102"], finding["validation"]["nrmse_after"]["TI-102"]
    # the bias explained, TI-102 fits as well as the twin fits the same data without the bias (the twin's
    # constant kht cannot follow the plant's fouling, so neither reaches the noise floor): the reference
    # is an estimate on the unbiased copy, not diagnose's own output; 10 % for the two fits' budgets
    from trackingbox.estimation import estimate

    plain = estimate(_copy_case(hx_bench, tmp_path / "plain"), maxiter=SETTINGS["maxiter"])
    assert after < 1.1 * plain.validation_nrmse["TI-102"] < before
    # the patch: <Twin>Diagnosed.mo written and compiled, naming the effect; a spec for the patched twin
    assert doc["patch"]["model"].endswith("TwinDiagnosed")
    assert (tmp_path / "patched" / "TwinDiagnosed.mo").read_text() == doc["patch"]["source"]
    assert "sensor-bias on TI-102" in doc["patch"]["source"]
    patched = load_spec(doc["patch"]["spec"])
    assert patched.outputs["TI-102"] != spec.outputs["TI-102"] and Path(doc["patch"]["fmu"]).is_file()
    text = (tmp_path / "report" / "diagnosis.md").read_text()
    assert "sensor-bias" in text and "```diff" in text and (tmp_path / "report" / "gap_TI-102.png").is_file()


@pytest.mark.compile
def test_bad_input_is_one_error_line_and_exit_2(hx_bench, tmp_path, capsys):
    from trackingbox.cli import main

    assert main(["diagnose", str(tmp_path / "nope.toml")]) == 2
    assert capsys.readouterr().err.startswith("error: ")
    spec = _copy_case(hx_bench, tmp_path / "case")
    assert main(["diagnose", str(spec.path), "--effects", "sensor-bais"]) == 2
    err = capsys.readouterr().err
    assert "unknown effect 'sensor-bais'" in err and "did you mean 'sensor-bias'" in err


def test_held_out_data_decide_between_candidates_alike_on_training():
    from types import SimpleNamespace as NS

    where = NS(validation_tags={t: NS(samples=500, periods=()) for t in ("T", "T1", "T2")},
               significant=["T1", "T2"], tags={t: NS(periods=()) for t in ("T1", "T2")})
    a = cd.Candidate("sensor-bias", "T1", "sensor", "screen", delta_bic=100.0, validation_gain=0.5, noise_gain=3.0)
    b = cd.Candidate("sensor-bias", "T2", "sensor", "screen", delta_bic=95.0, validation_gain=0.6, noise_gain=4.0)
    c = cd.Candidate("sensor-drift", "T2", "sensor", "screen", delta_bic=60.0, validation_gain=0.9, noise_gain=9.0)
    verdict = jd.judge([a, b, c], where)
    assert verdict.verdict == "effect" and verdict.named is b
    assert "smaller validation gain" in verdict.reasons["sensor-bias@T1"][0]
    assert "by a BIC difference above 10" in verdict.reasons["sensor-drift@T2"][0]
    # a candidate whose tag shows no gap beyond noise is never named
    d = cd.Candidate("sensor-bias", "T3", "sensor", "screen", delta_bic=500.0, validation_gain=0.9, noise_gain=9.0)
    verdict = jd.judge([d], where)
    assert verdict.verdict != "effect" and "within noise" in verdict.reasons["sensor-bias@T3"][-1]
    # nothing passes but the residual is significant: unexplained, saying where
    where.significant = ["T"]
    where.tags = {"T": NS(periods=((0.0, 3600.0),))}
    verdict = jd.judge([cd.Candidate("sensor-bias", "T", "sensor", "screen", 5.0, 0.1, 0.1)], where)
    assert verdict.verdict == "unexplained" and verdict.unexplained == {"T": [(0.0, 3600.0)]}


def test_a_sensor_effect_must_gain_on_its_own_tag_and_harm_no_other():
    c = cd.Candidate("sensor-lag", "Z", "sensor", "screen", delta_bic=100.0, validation_gain=0.1, noise_gain=50.0,
                     noise_gains={"Z": 0.01, "T": 49.99})
    assert any("own tag Z" in r for r in jd.reasons_against(c, 500))
    c = cd.Candidate("sensor-bias", "T", "sensor", "screen", delta_bic=100.0, validation_gain=0.1, noise_gain=3.0,
                     noise_gains={"T": 5.0, "F": -2.0})
    assert any("makes F worse" in r for r in jd.reasons_against(c, 500))


def test_document_code_block_is_verbatim_in_markdown_and_html():
    from trackingbox.report.document import Document

    doc = Document("t")
    doc.code("-a < b\n+`c`\n", "diff")
    assert "```diff\n-a < b\n+`c`\n```" in doc.markdown()
    assert "<pre><code>-a &lt; b\n+`c`</code></pre>" in doc.html_body().replace("\n</code>", "</code>")
