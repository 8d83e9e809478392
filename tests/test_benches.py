"""Bench cases: scenario building blocks, written files, sensor noise, --set, CLI errors."""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from trackingbox.benches import scenario as sc

# --------------------------------------------------------------------------- scenario parts (fast)


def test_moves_start_at_base_and_stay_in_range():
    t = np.arange(0.0, 8 * 3600.0 + 1, 10.0)
    rng = np.random.default_rng(1)
    y = sc.moves(t, rng, base=1.0, low=0.7, high=1.3, mean_interval=1800.0, hold_start=900.0)
    assert np.all(y[t < 900.0] == 1.0)
    assert y.min() >= 0.7 - 1e-12 and y.max() <= 1.3 + 1e-12
    # with a mean interval of 30 min over 8 h there are changes (steps and ramps)
    changes = np.count_nonzero(np.abs(np.diff(y)) > 1e-12)
    assert changes > 5


def test_drift_is_bounded_random_walk_with_requested_spread():
    # Ornstein-Uhlenbeck: stationary std = sigma; long run average over many correlation times
    t = np.arange(0.0, 2000 * 3600.0, 60.0)
    y = sc.drift(t, np.random.default_rng(2), sigma=0.5, time_constant=3600.0)
    assert y[0] == 0.0
    assert abs(y.std() - 0.5) < 0.05
    # correlation after one time constant is exp(-1)
    lag = 60
    r = np.corrcoef(y[:-lag], y[lag:])[0, 1]
    assert abs(r - math.exp(-1.0)) < 0.05


def test_daily_profile_peaks_morning_and_evening():
    t = np.arange(0.0, 24 * 3600.0, 60.0)
    p = sc.daily_profile(t)
    hour = t / 3600.0
    assert 0.0 <= p.min() and p.max() <= 1.0
    assert p[(hour > 0.5) & (hour < 3)].max() < 0.25          # night is low
    morning = hour[(hour > 4) & (hour < 10)][np.argmax(p[(hour > 4) & (hour < 10)])]
    evening = hour[(hour > 16) & (hour < 22)][np.argmax(p[(hour > 16) & (hour < 22)])]
    assert abs(morning - 7.0) < 0.5 and abs(evening - 19.0) < 0.75
    # periodic: the next day repeats
    assert np.allclose(sc.daily_profile(t + 86400.0), p)


# --------------------------------------------------------------------------- compiled benches

from trackingbox import cli  # noqa: E402
from trackingbox.benches import make_bench  # noqa: E402
from trackingbox.errors import SpecError  # noqa: E402
from trackingbox.fmu import FMUModel  # noqa: E402
from trackingbox.spec import check_against_fmu, load_spec, loads_spec  # noqa: E402

HX = "TrackingBox.Benches.HeatExchanger"
HP = "TrackingBox.Benches.HeatProduction"


@pytest.fixture(scope="module")
def hx_fmus(fmu_cache):
    return {"plant_fmu": fmu_cache(f"{HX}.Plant"), "twin_fmu": fmu_cache(f"{HX}.Twin")}


@pytest.fixture(scope="module")
def hx_case(hx_fmus, tmp_path_factory):
    return make_bench("heat-exchanger", tmp_path_factory.mktemp("hx") / "case", seed=0, hours=2.0, **hx_fmus)


@pytest.fixture(scope="module")
def hp_case(fmu_cache, tmp_path_factory):
    return make_bench("heat-production", tmp_path_factory.mktemp("hp") / "case", seed=1, hours=2.0,
                      plant_fmu=fmu_cache(f"{HP}.Plant"), twin_fmu=fmu_cache(f"{HP}.Twin"))


def clean_plant(case, outputs, hold=4 * 3600.0):
    """Noise-free plant outputs on the measurement grid, simulated here from the true inputs.

    The plant first runs *hold* seconds with the first input row held, which brings it
    to the steady state the measured period starts from.
    """
    inputs = pd.read_csv(case.plant_inputs)
    shifted = inputs.copy()
    shifted["time"] = inputs["time"] + hold
    frame = pd.concat([inputs.iloc[[0]].assign(time=0.0), shifted], ignore_index=True)
    truth = json.loads(case.truth_file.read_text())
    with FMUModel(case.plant_fmu) as model:
        res = model.simulate(stop_time=float(shifted["time"].iloc[-1]), output_interval=10.0, inputs=frame,
                             parameters=truth["overrides"], outputs=outputs)
    res = res[res["time"] >= hold - 1e-9].reset_index(drop=True)
    res["time"] -= hold
    return inputs, res


@pytest.mark.compile
def test_hx_case_files_and_spec(hx_case):
    spec = load_spec(hx_case.spec)
    check_against_fmu(spec)
    meas = pd.read_csv(hx_case.measurements)
    assert list(meas.columns) == ["time", *spec.tags]
    # 2 h at 10 s sampling, time in seconds from 0
    assert len(meas) == 721 and meas["time"].iloc[0] == 0.0 and meas["time"].iloc[-1] == 7200.0
    assert spec.sample_time == 10.0
    assert spec.windows == {"training": (0.0, 3600.0), "validation": (3600.0, 7200.0)}
    assert spec.parameter("hx.kht").start == 1000.0
    assert spec.source.model == f"{HX}.Twin" and (spec.source.path / "package.mo").is_file()
    # the plant is the fouled exchanger of Plant.mo
    assert hx_case.truth == {"hx.kht": 910.0}
    assert json.loads(hx_case.truth_file.read_text())["parameters"] == {"hx.kht": 910.0}


@pytest.mark.compile
def test_check_against_fmu_names_wrong_variables(hx_case):
    text = hx_case.spec.read_text().replace('"mHot_flow"', '"mHot_flw"').replace('name = "hx.kht"',
                                                                                  'name = "hx.kth"')
    spec = loads_spec(text, hx_case.spec)
    with pytest.raises(SpecError) as info:
        check_against_fmu(spec)
    msg = str(info.value)
    assert "'mHot_flw'" in msg and "did you mean 'mHot_flow'" in msg
    assert "'hx.kth'" in msg and "did you mean 'hx.kht'" in msg


@pytest.mark.compile
def test_check_against_fmu_rejects_bounds_wider_than_the_model_declares(hx_case):
    # PartialBench.mo declares hx.kht(min=500, max=1500)
    text = hx_case.spec.read_text().replace("min = 500.0", "min = 400.0")
    with pytest.raises(SpecError, match=r"min = 400\.0 of parameter 'hx.kht' is below the min = 500\.0"):
        check_against_fmu(loads_spec(text, hx_case.spec))


@pytest.mark.compile
def test_hx_sensor_noise_matches_requested_sigma(hx_case):
    inputs, clean = clean_plant(hx_case, ["ThOut", "TcOut"], hold=3600.0)
    meas = pd.read_csv(hx_case.measurements)
    n = len(meas)
    assert np.allclose(clean["time"], meas["time"])
    for tag, var in (("TI-102", "ThOut"), ("TI-202", "TcOut")):
        e = meas[tag].to_numpy() - clean[var].to_numpy()
        assert abs(e.std() - 0.1) < 0.01, tag                    # 0.1 K; sampling error ~2.6 %
        assert abs(e.mean()) < 4 * 0.1 / math.sqrt(n), tag       # unbiased
    for tag, var in (("TI-100", "ThIn"), ("TI-200", "TcIn")):
        e = meas[tag].to_numpy() - inputs[var].to_numpy()
        assert abs(e.std() - 0.1) < 0.01, tag
    for tag, var in (("FI-101", "mHot_flow"), ("FI-201", "mCold_flow")):
        rel = meas[tag].to_numpy() / inputs[var].to_numpy() - 1.0
        assert abs(rel.std() - 0.01) < 0.001, tag                 # 1 % of reading


@pytest.mark.compile
def test_set_lower_kht_warms_hot_outlet_and_cools_cold_outlet(hx_fmus, tmp_path):
    base = make_bench("heat-exchanger", tmp_path / "base", seed=5, hours=1.0, **hx_fmus)
    fouled = make_bench("heat-exchanger", tmp_path / "fouled", seed=5, hours=1.0,
                        overrides={"hx.kht": 700.0}, **hx_fmus)
    assert fouled.truth == {"hx.kht": 700.0}
    assert json.loads(fouled.truth_file.read_text())["overrides"] == {"hx.kht": 700.0}
    a = pd.read_csv(base.measurements)
    b = pd.read_csv(fouled.measurements)
    u = pd.read_csv(base.plant_inputs)
    # same seed: same scenario and noise; only the physics differs
    assert np.array_equal(a["FI-101"], b["FI-101"])
    d_hot = (b["TI-102"] - a["TI-102"]).to_numpy()
    d_cold = (b["TI-202"] - a["TI-202"]).to_numpy()
    assert d_hot.mean() > 2.0            # less heat transferred: the hot stream leaves warmer ...
    assert d_cold.mean() < -1.0          # ... and the cold stream cooler
    # energy balance: the heat the hot side keeps is the heat the cold side misses
    kept = (u["mHot_flow"] * d_hot).mean()
    missed = -(u["mCold_flow"] * d_cold).mean()
    assert kept == pytest.approx(missed, rel=0.05)


@pytest.mark.compile
def test_seed_reproduces_and_changes_the_case(hx_fmus, hx_case, tmp_path):
    again = make_bench("heat-exchanger", tmp_path / "again", seed=0, hours=2.0, **hx_fmus)
    other = make_bench("heat-exchanger", tmp_path / "other", seed=1, hours=2.0, **hx_fmus)
    assert again.measurements.read_bytes() == hx_case.measurements.read_bytes()
    a = pd.read_csv(hx_case.plant_inputs)
    b = pd.read_csv(other.plant_inputs)
    assert not np.allclose(a["mHot_flow"], b["mHot_flow"])


@pytest.mark.compile
@pytest.mark.parametrize("assignment, expected", [
    ("hx.khtt=900", "did you mean 'hx.kht'"),
    ("hx.kht=-5", "outside its declared range"),
])
def test_bad_set_exits_2_and_writes_nothing(hx_fmus, tmp_path, capsys, assignment, expected):
    out = tmp_path / "case"
    code = cli.main(["bench", "heat-exchanger", "--out", str(out), "--set", assignment, "--hours", "0.5",
                     "--plant-fmu", str(hx_fmus["plant_fmu"]), "--twin-fmu", str(hx_fmus["twin_fmu"])])
    assert code == 2
    assert expected in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.compile
def test_cli_json_summary(hx_fmus, tmp_path, capsys):
    out = tmp_path / "case"
    code = cli.main(["bench", "heat-exchanger", "--out", str(out), "--hours", "0.5", "--seed", "2",
                     "--set", "hx.kht=950", "--json",
                     "--plant-fmu", str(hx_fmus["plant_fmu"]), "--twin-fmu", str(hx_fmus["twin_fmu"])])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["truth"] == {"hx.kht": 950.0} and doc["seed"] == 2 and doc["hours"] == 0.5
    assert sorted(p.name for p in out.iterdir()) == ["measurements.csv", "plant.fmu", "plant_inputs.csv",
                                                     "spec.toml", "truth.json", "twin.fmu"]
    assert len(pd.read_csv(out / "measurements.csv")) == 181


@pytest.mark.compile
def test_hp_case_spec_states_and_level_noise(hp_case):
    spec = load_spec(hp_case.spec)
    check_against_fmu(spec)
    meas = pd.read_csv(hp_case.measurements)
    assert list(meas.columns) == ["time", *spec.tags]
    assert [s.tag for s in spec.states] == ["LI-100", "LI-200", "LI-400"]
    assert [s.correction for s in spec.states] == ["T100_m_flow_corr", "T200_m_flow_corr", "T400_m_flow_corr"]
    # the method notes' table: 14 candidates with their initial values and bounds
    assert len(spec.parameters) == 14
    assert spec.parameter("PU200.VFlowDesign") == type(spec.parameters[0])("PU200.VFlowDesign", 8.3e-5, 7.5e-5,
                                                                           9.16e-5)
    # Plant.mo: HEX300 fouled to 920, PU100 worn to 6.3e-5 m3/s
    assert hp_case.truth["HEX300.kht"] == 920.0 and hp_case.truth["PU100.VFlowDesign"] == 6.3e-5
    _, clean = clean_plant(hp_case, ["LI_100", "LI_200", "TI_302"])
    for tag, var, sigma in (("LI-100", "LI_100", 0.005), ("LI-200", "LI_200", 0.005),
                            ("TI-302", "TI_302", 0.1)):
        e = meas[tag].to_numpy() - clean[var].to_numpy()
        assert abs(e.std() - sigma) < 0.1 * sigma, tag
