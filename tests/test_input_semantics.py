"""How measured inputs reach the twin between samples: the spec's ``[data] inputs`` (issue 30, item 3).

One rule, ``"linear"`` (interpolated) or ``"hold"`` (the last sample held), the same on both FMI
interfaces: a model-exchange FMU integrates the interpolated or held input; a co-simulation FMU
gets each part's value and slope where it interpolates inputs (FMI 2 ``canInterpolateInputs``),
else midpoint sub-steps of the ramp, or the held value. Independent reference: the closed-form
response of a first-order lag to a piecewise-linear or piecewise-constant input
(:func:`trackingbox.testing.lag_fmu.lag_response`), with the lag built from one C source as a
model-exchange FMU and as co-simulation FMUs that do and do not interpolate inputs.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trackingbox.errors import SpecError
from trackingbox.estimation import estimate
from trackingbox.fmu import FMUModel
from trackingbox.spec import load_spec
from trackingbox.testing.lag_fmu import build_lag_fmus, lag_response

K_TRUE = 0.004   # 1/s: a 250 s time constant
X0 = 40.0


@pytest.fixture(scope="module")
def lags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return build_lag_fmus(tmp_path_factory.mktemp("lag"))


def _input(t: np.ndarray) -> np.ndarray:
    """A slowly wandering input, sampled every 60 s, with a step: what a DCS historian records."""
    rng = np.random.default_rng(7)
    return 50.0 + np.cumsum(rng.normal(0.0, 1.5, t.size)) + 8.0 * (t >= 1800.0)


@pytest.mark.parametrize("rule", ["linear", "hold"])
@pytest.mark.parametrize("variant", ["me", "cs", "cs-interpolating"])
def test_each_interface_follows_the_rule(lags, variant, rule):
    t = np.arange(0.0, 3601.0, 60.0)
    u = _input(t)
    exact = lag_response(t, u, K_TRUE, X0, rule)
    with FMUModel(lags[variant], tolerance=1e-9) as m:
        df = m.simulate(stop_time=3600.0, output_interval=60.0, inputs=pd.DataFrame({"time": t, "u": u}),
                        parameters={"k": K_TRUE, "x0": X0}, outputs=["y"], input_rule=rule)
    got = df["y"].to_numpy()
    # exact steps (co-simulation, except the linear rule without interpolation: midpoint sub-steps) or
    # CVODE at rtol 1e-9 (model exchange)
    tol = 5e-3 if (variant, rule) == ("cs", "linear") else 1e-5
    assert np.max(np.abs(got - exact)) <= tol
    # the rules differ by far more than that on this input
    other = lag_response(t, u, K_TRUE, X0, "hold" if rule == "linear" else "linear")
    assert np.max(np.abs(other - exact)) > 0.5


@pytest.mark.parametrize("native", [True, False])
def test_hold_on_model_exchange_of_fmi3_native_and_python(first_order_fmu, native):
    """The CasADi first-order twin (x' = (u - x)/tau - k x): a lag of rate 1/tau + k towards u/(1 + k tau)."""
    tau, k, x0 = 100.0, 0.003, 38.0
    t = np.arange(0.0, 1201.0, 30.0)
    u = 50.0 + 10.0 * np.sin(t / 200.0)
    rate = 1.0 / tau + k
    with FMUModel(first_order_fmu, tolerance=1e-10) as m:
        for rule in ("linear", "hold"):
            st = m.stepper(parameters={"k": k, "x": x0}, inputs=pd.DataFrame({"time": t, "u": u}),
                           input_rule=rule, native=native)
            ys = [float(st.get(["y"])[0])]
            for tk in t[1:]:
                st.step(float(tk))
                ys.append(float(st.get(["y"])[0]))
            exact = lag_response(t, u / (tau * rate), rate, x0, rule)
            assert np.max(np.abs(np.array(ys) - exact)) <= 1e-5, rule


def _case(root: Path, fmu: Path, rule: str, noise: float = 0.02) -> Path:
    """Measurements of the lag (k = K_TRUE) made by the closed form under *rule*, and a spec under *rule*."""
    root.mkdir(parents=True, exist_ok=True)
    t = np.arange(0.0, 7201.0, 60.0)
    u = _input(t)
    y = lag_response(t, u, K_TRUE, X0, rule) + np.random.default_rng(3).normal(0.0, noise, t.size)
    pd.DataFrame({"time": t, "FI": u, "TI": y}).to_csv(root / "measurements.csv", index=False)
    (root / "twin.fmu").write_bytes(fmu.read_bytes())
    (root / "spec.toml").write_text(
        'twin = "twin.fmu"\nmeasurements = "measurements.csv"\nsample_time = 60.0\n\n'
        '[inputs]\n"FI" = "u"\n\n[outputs]\n"TI" = "y"\n\n'
        '[[parameters]]\nname = "k"\nstart = 0.01\nmin = 0.001\nmax = 0.02\n\n'
        f'[fixed]\nx0 = {X0}\n\n'
        "[windows]\ntraining = [0.0, 3600.0]\nvalidation = [3600.0, 7200.0]\n\n"
        f'[data]\ninputs = "{rule}"\n', encoding="utf-8")
    return root / "spec.toml"


@pytest.mark.parametrize("rule", ["linear", "hold"])
def test_model_exchange_and_co_simulation_builds_give_the_same_estimate(lags, tmp_path, rule):
    found = {}
    for variant in ("me", "cs", "cs-interpolating"):
        spec = load_spec(_case(tmp_path / variant, lags[variant], rule))
        found[variant] = estimate(spec, seed=0, maxiter=4, popsize=8).parameters["k"]
    # the truth, within what 0.02 of noise on 60 samples allows
    for variant, k in found.items():
        assert k == pytest.approx(K_TRUE, rel=0.01), (variant, found)
    assert found["cs-interpolating"] == pytest.approx(found["me"], rel=1e-3)
    assert found["cs"] == pytest.approx(found["me"], rel=5e-3 if rule == "linear" else 1e-3)


def test_the_wrong_rule_moves_the_estimate(lags, tmp_path):
    """Data made with held inputs, read as interpolated: the estimate moves (what issue 30 saw as 42 %)."""
    spec = _case(tmp_path / "wrong", lags["me"], "hold")
    text = spec.read_text().replace('inputs = "hold"', 'inputs = "linear"')
    spec.write_text(text)
    k = estimate(load_spec(spec), seed=0, maxiter=4, popsize=8).parameters["k"]
    assert abs(k / K_TRUE - 1.0) > 0.05


def test_an_unknown_rule_is_refused_naming_the_choices(lags, tmp_path):
    spec = _case(tmp_path / "bad", lags["me"], "linear")
    spec.write_text(spec.read_text().replace('inputs = "linear"', 'inputs = "held"'))
    with pytest.raises(SpecError, match=r"\[data\] inputs = 'held' is not one of 'linear', 'hold'.*did you mean"):
        load_spec(spec)


def test_tracking_and_validation_inputs_follow_the_rule(first_order_fmu, tmp_path):
    """A plant whose input moves in steps between 10 s samples, tracked under "hold": the tracked k
    reaches the plant's, and the untracked twin equals the plant run with the twin's k under "hold"."""
    from trackingbox.tracking.runtime import track

    t = np.arange(0.0, 6001.0, 10.0)
    u = 50.0 + 10.0 * (t >= 2000.0) - 5.0 * (t >= 4000.0) + 3.0 * np.sin(t / 300.0)
    table = pd.DataFrame({"time": t, "u": u})
    with FMUModel(first_order_fmu) as m:
        plant = m.simulate(stop_time=6000.0, output_interval=10.0, inputs=table, outputs=["y"], input_rule="hold",
                           parameters={"k": 0.004, "x": 50.0 / 1.4})
        twin = m.simulate(stop_time=6000.0, output_interval=10.0, inputs=table, outputs=["y"], input_rule="hold",
                          parameters={"k": 0.003})
    pd.DataFrame({"time": t, "FI": u, "TI": plant["y"]}).to_csv(tmp_path / "measurements.csv", index=False)
    (tmp_path / "twin.fmu").write_bytes(Path(first_order_fmu).read_bytes())
    from trackingbox.testing.specs import first_order_spec

    (tmp_path / "spec.toml").write_text(first_order_spec(
        start=0.003, lower=0.001, upper=0.01, training=(0.0, 3000.0), validation=(3000.0, 6000.0),
        extra='[data]\ninputs = "hold"', hold_until=200.0,
        pair={"gain": -2551.0, "time_constant": 71.0, "lambda": 1.0}))
    result = track(load_spec(tmp_path / "spec.toml"), out_dir=tmp_path / "out")
    df = pd.read_csv(result.csv)
    np.testing.assert_allclose(df["untracked:TI"], twin["y"], atol=1e-4)
    assert df["parameter:k"].iloc[-50:].mean() == pytest.approx(0.004, rel=0.01)
