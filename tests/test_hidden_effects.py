"""The hidden-effect suite: each plant variant differs from the plain plant as its physics says.

Expectations come from outside each variant's own equation where possible: the
plain plant simulated at the fouled coefficient or at the reduced flow, an
energy or mass balance over the component with the effect's formula written
here, a sensor lag integrated here with scipy. Effects that start at the end of
the bench's warm-up are moved to an earlier ``tStart`` (a tunable parameter) to
keep the runs short.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from trackingbox.benches import bench_definition

pytestmark = pytest.mark.compile

HX = "TrackingBox.Benches.HeatExchanger"
HP = "TrackingBox.Benches.HeatProduction"


def _run(fmu, stop, names, *, parameters=None, inputs=None, interval=10.0):
    from trackingbox.fmu import FMUModel

    model = FMUModel(fmu)
    try:
        return model.simulate(stop_time=stop, output_interval=interval, outputs=names,
                              parameters=parameters or {}, inputs=inputs)
    finally:
        model.close()


def test_every_case_names_a_compilable_variant():
    for bench in ("heat-exchanger", "heat-production"):
        cases = bench_definition(bench).hidden
        assert cases, bench
        in_library = [c for c in cases.values() if c.effect is not None]
        assert {c.effect for c in in_library} >= {"fouling", "heat-loss", "sensor-drift"}
        for c in cases.values():
            assert c.model.startswith(f"TrackingBox.Benches.{'HeatExchanger' if bench == 'heat-exchanger' else 'HeatProduction'}.Hidden.")
            assert c.affected
    assert [c.name for c in bench_definition("heat-exchanger").hidden.values() if c.effect is None] == ["bypass"]


def test_hx_fouling_exp_is_the_plain_plant_at_the_fouled_coefficient(fmu_cache):
    # quasi-steady: the coefficient's time constant (4 h) is 100 times the residence time (2 min)
    df = _run(fmu_cache(f"{HX}.Hidden.FoulingExp"), 7200.0, ["ThOut", "TcOut"], parameters={"tStart": 600.0})
    t_end = 7200.0
    kht = 910.0 * (1 - 0.25 * (1 - np.exp(-(t_end - 600.0) / 14400.0)))
    plain = _run(fmu_cache(f"{HX}.Plant"), 1800.0, ["ThOut", "TcOut"], parameters={"hx.kht": kht})
    assert abs(df["ThOut"].iloc[-1] - plain["ThOut"].iloc[-1]) < 0.05
    assert abs(df["TcOut"].iloc[-1] - plain["TcOut"].iloc[-1]) < 0.05
    clean = _run(fmu_cache(f"{HX}.Plant"), 1800.0, ["ThOut"])
    assert df["ThOut"].iloc[-1] - clean["ThOut"].iloc[-1] > 1.0  # fouled: the hot outlet is warmer


def test_hx_heat_loss_leaves_the_hot_stream(fmu_cache):
    df = _run(fmu_cache(f"{HX}.Hidden.HeatLoss"), 1800.0, ["ThIn", "ThOut", "hx.Q_total", "hx.T1[1]"])
    last = df.iloc[-1]
    loss = 40.0 * (last["hx.T1[1]"] - 291.15) ** 1.25
    assert 5000 < loss < 9000
    # hot side at steady state: m*cp*(ThIn - ThOut) = heat to the cold side + loss (cp ~4190 at 50-90 degC)
    assert abs(1.0 * 4190.0 * (last["ThIn"] - last["ThOut"]) - (last["hx.Q_total"] + loss)) < 0.01 * loss + 1500
    plain = _run(fmu_cache(f"{HX}.Plant"), 1800.0, ["ThOut"])
    assert plain["ThOut"].iloc[-1] - last["ThOut"] > 0.5 * loss / 4190.0


def test_hx_sensor_drift_changes_only_the_reading(fmu_cache):
    df = _run(fmu_cache(f"{HX}.Hidden.SensorDrift"), 3600.0, ["ThOut", "ThOut_sensor"], parameters={"tStart": 600.0})
    plain = _run(fmu_cache(f"{HX}.Plant"), 3600.0, ["ThOut"])
    t = df["time"].to_numpy()
    np.testing.assert_allclose(df["ThOut"], plain["ThOut"], atol=1e-6)
    expected = 1.5 * (1 - np.exp(-np.maximum(t - 600.0, 0) / 20000.0))
    np.testing.assert_allclose(df["ThOut_sensor"] - plain["ThOut"], expected, atol=1e-6)


def test_hx_sensor_lag_is_second_order(fmu_cache):
    t = np.arange(0.0, 2401.0, 10.0)
    inputs = pd.DataFrame({"time": t, "ThIn": 363.15, "TcIn": np.where(t < 1200, 283.15, 288.15),
                           "mHot_flow": 1.0, "mCold_flow": 2.0})
    df = _run(fmu_cache(f"{HX}.Hidden.SensorLag"), 2400.0, ["TcOut", "TcOut_sensor"], inputs=inputs, interval=2.0)
    tt, x = df["time"].to_numpy(), df["TcOut"].to_numpy()

    def rhs(time, s):
        xi = np.interp(time, tt, x)
        return [(xi - s[0]) / 90.0, (s[0] - s[1]) / 30.0]

    sol = solve_ivp(rhs, (0.0, 2400.0), [308.15, 308.15], t_eval=tt, max_step=2.0, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(df["TcOut_sensor"], sol.y[1], atol=0.02)
    # a first-order lag of the same total delay would lead the reading early in the step
    assert np.max(np.abs(df["TcOut_sensor"] - df["TcOut"])) > 0.5


def test_hx_bypass_is_the_exchanger_at_the_reduced_flow(fmu_cache):
    df = _run(fmu_cache(f"{HX}.Hidden.Bypass"), 1800.0, ["ThOut", "TcOut"])
    plain = _run(fmu_cache(f"{HX}.Plant"), 1800.0, ["ThOut", "TcOut"], inputs=pd.DataFrame(
        {"time": [0.0, 1800.0], "ThIn": 363.15, "TcIn": 283.15, "mHot_flow": 0.9, "mCold_flow": 2.0}))
    assert abs(df["TcOut"].iloc[-1] - plain["TcOut"].iloc[-1]) < 1e-3
    assert abs(df["ThOut"].iloc[-1] - (0.9 * plain["ThOut"].iloc[-1] + 0.1 * 363.15)) < 1e-3


def test_hp_leak_grows_with_level(fmu_cache):
    names = ["T200.level", "T200.rho", "T200.m_flow_in", "T200.m_flow_out", "T200.m_flow_corr_total"]
    df = _run(fmu_cache(f"{HP}.Hidden.LeakLevel"), 900.0, names, interval=1.0)
    t = df["time"].to_numpy()
    rate = df["T200.rho"] * 0.3 * np.gradient(df["T200.level"].to_numpy(), t)
    leak = 0.0045 * np.sqrt(df["T200.level"])
    balance = df["T200.m_flow_in"] - df["T200.m_flow_out"] + df["T200.m_flow_corr_total"] - leak
    np.testing.assert_allclose(rate[5:-5], balance[5:-5], atol=2e-4)
    assert 0.0039 < leak.iloc[0] < 0.0042  # 4 g/s at 0.8 m


def test_hp_heat_loss_in_the_t100_energy_balance(fmu_cache):
    names = ["T100.T", "T100.m", "T100.cp", "T100.H_flow_in", "T100.Q_flow_in", "T100.Q_loss", "TAmb", "QI_100"]
    df = _run(fmu_cache(f"{HP}.Hidden.HeatLoss"), 900.0, names, interval=1.0)
    t = df["time"].to_numpy()
    stored = df["T100.m"] * df["T100.cp"] * np.gradient(df["T100.T"].to_numpy(), t)
    extra = 8.0 * (df["T100.T"] - df["TAmb"]) ** 1.25
    balance = df["T100.H_flow_in"] + df["T100.Q_flow_in"] - df["T100.Q_loss"] - extra
    np.testing.assert_allclose(stored[5:-5], balance[5:-5], atol=30.0)
    assert 550 < extra.iloc[0] < 800


def test_hp_fouling_and_drift(fmu_cache):
    fouled = _run(fmu_cache(f"{HP}.Hidden.FoulingExp"), 1800.0, ["HEX300.kht_internal", "TI_301"],
                  parameters={"tStart": 0.0, "tau": 1000.0})
    plain = _run(fmu_cache(f"{HP}.Plant"), 1800.0, ["TI_301"])
    # kht falls towards 65 % of the plant's 920; the hot side of HEX300 gives less heat away
    assert abs(fouled["HEX300.kht_internal"].iloc[-1] - 920.0 * (1 - 0.35 * (1 - np.exp(-1.8)))) < 0.5
    assert fouled["TI_301"].iloc[-1] > plain["TI_301"].iloc[-1] + 0.2
    drift = _run(fmu_cache(f"{HP}.Hidden.SensorDrift"), 1800.0, ["TI_100", "TI_100_sensor"],
                 parameters={"tStart": 0.0})
    plain = _run(fmu_cache(f"{HP}.Plant"), 1800.0, ["TI_100"])
    np.testing.assert_allclose(drift["TI_100"], plain["TI_100"], atol=1e-6)
    t = drift["time"].to_numpy()
    np.testing.assert_allclose(drift["TI_100_sensor"] - drift["TI_100"], -2.0 * (1 - np.exp(-t / 50000.0)),
                               atol=1e-6)


def test_bench_hidden_case_and_noise_scale(fmu_cache, tmp_path):
    import json

    from trackingbox.benches import make_bench
    from trackingbox.spec import load_spec

    fmus = {"plant_fmu": fmu_cache(f"{HX}.Hidden.SensorDrift"), "twin_fmu": fmu_cache(f"{HX}.Twin")}
    cases = {s: make_bench("heat-exchanger", tmp_path / f"x{s}", seed=4, hours=1.0, hidden="sensor-drift",
                           noise_scale=s, **fmus) for s in (1.0, 3.0)}
    truth = json.loads(cases[3.0].truth_file.read_text())
    assert truth["hidden"]["effect"] == "sensor-drift" and truth["hidden"]["target"] == "TI-102"
    assert truth["noise_scale"] == 3.0 and truth["plant_model"].endswith("Hidden.SensorDrift")
    spec = load_spec(cases[3.0].spec)
    assert spec.outputs["TI-102"] == "ThOut"  # the twin and spec are the plain bench's
    # the same seed draws the same numbers: input noise (measured - true input) scales by exactly 3,
    # and its standard deviation is 3 x 0.1 K for a thermometer
    noise = {}
    for s, case in cases.items():
        meas, true = pd.read_csv(case.measurements), pd.read_csv(case.plant_inputs)
        noise[s] = (meas["TI-100"] - true["ThIn"]).to_numpy()
    np.testing.assert_allclose(noise[3.0], 3.0 * noise[1.0], atol=2e-5)  # CSV keeps 9 digits
    assert 0.25 < noise[3.0].std() < 0.35
    with pytest.raises(Exception, match=r"unknown hidden-effect case 'leak' of bench 'heat-exchanger'"):
        make_bench("heat-exchanger", tmp_path / "bad", hidden="leak", **fmus)
    assert not (tmp_path / "bad").exists()


def test_hp_suite_twin_lacks_only_the_plant_values(fmu_cache):
    """The heat-production suite twin at the plant's parameter values is the plain plant; the bench's own
    (linear-curve) twin at the same values is not, by far more than the sensors' noise."""
    from fmpy import read_model_description

    from trackingbox.benches.heat_production import DEFINITION

    plant_fmu = fmu_cache(f"{HP}.Plant")
    starts = {v.name: float(v.start) for v in read_model_description(plant_fmu).modelVariables
              if v.causality == "parameter" and v.type in ("Real", "Float64") and v.start is not None}
    values = {p.name: starts[p.name] for p in DEFINITION.parameters}
    assert values["HEX300.kht"] == 920.0 and values["PU100.VFlowDesign"] == 6.3e-5  # Plant.mo's degraded values
    tags = {s.plant: s for s in DEFINITION.outputs}
    plant = _run(plant_fmu, 3600.0, list(tags))
    suite = _run(fmu_cache(DEFINITION.suite_twin_model), 3600.0, list(tags), parameters=values)
    own = _run(fmu_cache(DEFINITION.twin_model), 3600.0, list(tags), parameters=values)

    def sigma(name):  # the sensor's noise standard deviation at the plant's mean reading
        s, relative = tags[name].noise
        return s * abs(plant[name]).mean() if relative else s

    for name in tags:
        np.testing.assert_allclose(suite[name], plant[name], atol=max(0.01 * sigma(name), 1e-9), err_msg=name)
    worst = max(np.max(np.abs(own[n] - plant[n])) / sigma(n) for n in tags if sigma(n) > 0)
    assert worst > 5.0  # linear curves: several noise standard deviations off on some tag


def test_hp_hidden_cases_are_written_against_the_suite_twin(fmu_cache, tmp_path):
    import json

    from trackingbox.benches import make_bench
    from trackingbox.benches.heat_production import DEFINITION
    from trackingbox.spec import load_spec

    plant = fmu_cache(f"{HP}.Hidden.LeakLevel")
    suite = make_bench("heat-production", tmp_path / "suite", hours=0.5, hidden="leak-level", plant_fmu=plant,
                       twin_fmu=fmu_cache(DEFINITION.suite_twin_model))
    own = make_bench("heat-production", tmp_path / "own", hours=0.5, hidden="leak-level", plant_fmu=plant,
                     twin_fmu=fmu_cache(DEFINITION.twin_model), suite_twin=False)
    for case, model in ((suite, DEFINITION.suite_twin_model), (own, DEFINITION.twin_model)):
        assert load_spec(case.spec).source.model == model
        assert json.loads(case.truth_file.read_text())["twin_model"] == model
    assert "--no-suite-twin" in own.spec.read_text() and "--suite-twin" not in suite.spec.read_text()
    # the same plant and seed: the measurements do not depend on the twin
    pd.testing.assert_frame_equal(pd.read_csv(suite.measurements), pd.read_csv(own.measurements))
