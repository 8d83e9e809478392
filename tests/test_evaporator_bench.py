"""The evaporator bench: scenario, stoppages, the case it writes and the pipeline's key properties.

Fast tests check the scenario against the issue's numbers (several stoppages a day,
feed to ~0 within a minute, held 10-60 min; the notes' last-effect ranges) and the
done-criteria checks on a hand-built run. The ``compile`` tests build a short case
from the Plant and Twin (compiled once per session) and check it against the
plant's own truth; the 3-day run belongs to ``scripts/demo --bench evaporator``
and ``scripts/bench_tracking``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trackingbox.benches import BENCHES, bench_definition
from trackingbox.benches.evaporator import (
    NOMINAL,
    STOPPED_FRACTION,
    Stoppage,
    evaporator_inputs,
    stoppage_factor,
    stoppage_schedule,
    truth_on,
)
from trackingbox.data import stoppage_mask


def test_registered() -> None:
    assert "evaporator" in BENCHES
    d = bench_definition("evaporator")
    # the contract's fixed names: inputs and outputs of Plant and Twin, plus the steam-chest
    # pressure (the notes' "PI steam"), added for pairing the heat-transfer parameter, and the pump's
    # discharge pressure (the notes' "discharge PI" of the pump's wear)
    assert {s.plant for s in d.inputs} == {"feedFlowSet", "feedDS", "feedT", "steamP", "nextP"}
    assert {s.plant for s in d.outputs} == {
        "FI_feed", "FI_product", "FI_condensate", "PI_vapour", "PI_flash", "TI_body", "TI_flash", "LI_body",
        "LI_flash", "LI_condensate", "DI_product", "ZI_inlet", "ZI_outlet",
        "PI_steamChest", "PI_pump"}
    assert {(s.variable, s.correction) for s in d.states} == {
        ("LI_body", "body_m_flow_corr"), ("LI_flash", "flash_m_flow_corr"), ("LI_condensate", "cond_m_flow_corr")}


@pytest.mark.parametrize("seed", range(8))
def test_stoppages_several_a_day_within_a_minute_held_10_to_60_min(seed: int) -> None:
    days = 3
    stops = stoppage_schedule(days * 86400.0, np.random.default_rng(seed))
    assert len(stops) >= 2 * days - 1, "several stoppages a day"
    for s in stops:
        assert s.ramp_down <= 60.0
        held = s.restart - (s.start + s.ramp_down)
        assert 600.0 <= held <= 3600.0
    for a, b in zip(stops, stops[1:]):
        assert b.start > a.end, "stoppages do not overlap"


def test_stoppage_factor_by_hand() -> None:
    s = Stoppage(start=100.0, restart=1000.0, ramp_down=50.0, ramp_up=200.0)
    t = np.array([0.0, 100.0, 125.0, 150.0, 500.0, 1000.0, 1100.0, 1200.0, 5000.0])
    # hand values: linear ramps between 1 and the floor 0.01
    expected = [1.0, 1.0, 1 - 0.99 * 0.5, 0.01, 0.01, 0.01, 0.01 + 0.99 * 0.5, 1.0, 1.0]
    assert np.allclose(stoppage_factor(t, [s], 0.01), expected)


def test_inputs_stay_in_the_notes_ranges_and_stop_to_near_zero() -> None:
    rng = np.random.default_rng(4)
    warm = 3600.0
    t = np.arange(0.0, warm + 3 * 86400.0 + 1, 10.0)
    stops = stoppage_schedule(3 * 86400.0, np.random.default_rng(4))
    u = evaporator_inputs(t, rng, warm, stops)
    assert 0.49 <= u["feedDS"].min() and u["feedDS"].max() <= 0.56   # last effect in: 50-55 % DS
    assert 3.0e5 <= u["steamP"].min() and u["steamP"].max() <= 4.5e5  # 3-4.5 bar(a)
    f0 = NOMINAL["feedFlowSet"]
    tm = t - warm
    for s in stops:
        held = (tm >= s.start + s.ramp_down) & (tm <= s.restart)
        assert u["feedFlowSet"][held].max() <= STOPPED_FRACTION * f0 + 1e-12
    # the data layer's stoppage rule finds every stoppage of the schedule, and nothing else
    mask = stoppage_mask(tm, u["feedFlowSet"], 0.3 * f0)
    for s in stops:
        assert mask[(tm >= s.start + s.ramp_down) & (tm <= s.restart)].all()
    running = np.ones(t.size, dtype=bool)
    for s in stops:
        running &= ~((tm >= s.start) & (tm <= s.end))
    assert not mask[running & (tm >= 0)].any()


def test_truth_on_interpolates_the_trajectory() -> None:
    truth = {"trajectories": {"effect.Rf": {"time": [0.0, 3600.0], "value": [0.0, 1e-4]}},
             "parameters": {"pump.dp0": 2e5}}
    assert np.allclose(truth_on(truth, "effect.Rf", [1800.0, 7200.0]), [5e-5, 1e-4])
    assert np.allclose(truth_on(truth, "pump.dp0", [0.0]), [2e5])
    assert truth_on(truth, "nothing", [0.0]) is None


def test_assess_on_a_hand_built_run(tmp_path: Path) -> None:
    """Errors of the fouling check, level and NRMSE checks, computed by hand on a made-up run."""
    from types import SimpleNamespace

    from trackingbox.benches.evaporator_report import assess
    from trackingbox.spec import PairSpec, ParameterSpec, StateSpec, StoppageRule

    t = np.arange(0.0, 48 * 3600.0 + 1, 600.0)
    truth_rf = 2e-4 * (1 - np.exp(-t / 86400.0))
    tracked = truth_rf + 3e-5  # 3e-5 / 6e-4 = 5 % of the bound range
    tracked[t > 40 * 3600.0] += 4e-5  # then 7e-5 / 6e-4 = 11.7 %
    frame = pd.DataFrame({"time": t, "parameter:effect.Rf": tracked,
                          "tracked:LI-6111": 0.5 + 0.1 * np.sin(t / 1e4)})
    csv = tmp_path / "tracking.csv"
    frame.to_csv(csv, index=False)
    spec = SimpleNamespace(
        pairs=[PairSpec("FI-6125", "effect.Rf", 1.0, 100.0, 1.0)],
        parameters=[ParameterSpec("effect.Rf", 0.0, 0.0, 6e-4)],
        states=[StateSpec("LI-6111", "LI_body", "body_m_flow_corr", 4.0)],
        data=SimpleNamespace(stoppage=StoppageRule("FI-6110", 0.6, 1800.0)))
    truth = {"trajectories": {"effect.Rf": {"time": t.tolist(), "value": truth_rf.tolist()}},
             "stoppages": [{"start": 20 * 3600.0, "end": 21 * 3600.0}]}
    res = assess(spec, csv, truth, nrmse={"FI-6125": (0.2, 0.05)}, heights={"LI-6111": 0.55})
    assert res.heat_transfer_pair == ("FI-6125", "effect.Rf")
    assert res.nrmse["FI-6125"][2] == pytest.approx(0.25) and res.nrmse_ok
    assert res.fouling is not None
    assert res.fouling.max_error == pytest.approx(7e-5 / 6e-4)
    assert res.fouling.max_error_stoppages == pytest.approx(3e-5 / 6e-4)
    assert not res.fouling.passed and res.fouling.within_bounds
    assert res.levels[0].max == pytest.approx(0.6, abs=1e-3) and not res.levels_ok  # 0.6 m > 0.55 m vessel


# --------------------------------------------------------------------------- compiled: a short case

EV = "TrackingBox.Benches.Evaporator"
#: One 40-min stoppage in a 10 h case (5 h training, 5 h validation), after the 1 h start-up hold.
STOP = Stoppage(start=6.0 * 3600.0, restart=6.0 * 3600.0 + 40 * 60.0, ramp_down=40.0, ramp_up=180.0)
#: Plant fouling that grows within hours instead of days (the asymptote and its time constant).
FAST_FOULING = {"RfInf": 2.0e-4, "tauFouling": 3 * 3600.0}


@pytest.fixture(scope="module")
def short_case(fmu_cache, tmp_path_factory):
    """A 10 h evaporator case, seed 1, one known stoppage, fast fouling; pairs from ``pair``."""
    from trackingbox.analysis.pair_stage import PairSettings, pair, spec_pairs
    from trackingbox.benches.evaporator import build, load_truth, slow_pairs
    from trackingbox.spec import load_spec, write_pairs

    out = tmp_path_factory.mktemp("evcase")
    twin = fmu_cache(f"{EV}.Twin")
    case = build(out, seed=1, hours=10.0, overrides=FAST_FOULING, plant_fmu=fmu_cache(f"{EV}.Plant"),
                 twin_fmu=twin, stoppages=[STOP])
    spec = load_spec(case.spec)
    # the spec's [pairing] (nothing frozen, as track runs the twin) but a 20-min closed loop, predicted and
    # tuned: the demo's 3 h would not settle inside this case's 5 h windows
    result = pair(spec, PairSettings(workers=1, closed_loop=1200.0))
    write_pairs(case.spec, spec_pairs(spec, result))
    spec = slow_pairs(case.spec, closed_loop=1200.0)
    return case, spec, result, load_truth(case.truth_file)


@pytest.mark.slow
@pytest.mark.compile
def test_case_is_a_historian_export_with_the_plants_fouling(short_case) -> None:
    case, spec, _, truth = short_case
    raw = pd.read_csv(case.measurements)
    # the historian's long export: ISO 8601 timestamps with an offset, every tag of the spec
    assert list(raw.columns) == ["tag", "time", "value"]
    assert str(raw["time"].iloc[0]).startswith("2026-01-12T06:0") and str(raw["time"].iloc[0]).endswith("+00:00")
    assert set(raw["tag"]) == set(spec.tags)
    # dead-band reporting: the feed setpoint (scanned every 2 s) is logged far less often than
    # scanned, but at least every heartbeat (600 s) while the link is up
    scans = 10 * 3600 / 2.0
    sp = raw[raw["tag"] == "FIC-6110.SP"]
    assert 10 * 3600 / 600 <= sp["value"].notna().sum() < 0.2 * scans
    # the plant fouls: the recorded resistance grows towards RfInf (3 time constants: 95 %)
    rf = np.asarray(truth["trajectories"]["effect.Rf"]["value"])
    assert np.all(np.diff(rf) >= -1e-12) and rf[-1] > 0.5 * FAST_FOULING["RfInf"]
    assert truth["stoppages"] == [STOP.to_json()]


@pytest.mark.slow
@pytest.mark.compile
def test_stoppage_is_masked_from_the_measurements(short_case) -> None:
    from trackingbox.data import MeasurementView, extend_mask

    _, spec, _, _ = short_case
    view = MeasurementView.from_spec(spec, "all")
    g = view.grid
    held = (g >= STOP.start + STOP.ramp_down + 60.0) & (g <= STOP.restart)
    assert view.stopped[held].all()
    # elsewhere only the historian's losses are masked: an input or the stoppage tag missing, and the
    # settle time after it
    lost = extend_mask(g, view.input_gap | view.stoppage_unknown, spec.data.stoppage.settle)
    assert not (view.stopped & ~lost)[g < STOP.start - 60.0].any()
    assert not (view.stopped & ~lost)[g > STOP.end + spec.data.stoppage.settle + 60.0].any()


@pytest.mark.slow
@pytest.mark.compile
def test_pairing_is_physical(short_case) -> None:
    from trackingbox.benches.evaporator_report import HEAT_TRANSFER_TAGS

    _, spec, result, _ = short_case
    pairs = {p.parameter: p.variable for p in spec.pairs}
    # the fouling resistance goes with the condensate flow, the effect's T or p, or the product DS
    assert pairs.get("effect.Rf") in HEAT_TRANSFER_TAGS, pairs
    left = {n for n, _ in result.pairing.left_out}
    for name in ("effect.Rf", "effect.dBPR", "inletValve.KvMax", "outletValve.KvMax", "pump.dp0", "pump.VMax"):
        assert name in pairs or name in left, f"{name} neither paired nor left out with a reason"


@pytest.fixture(scope="module")
def tracked(short_case, tmp_path_factory):
    """``track`` of the short case on its validation window, and assess()'s measure of it (settled after 4 h)."""
    from trackingbox.benches.evaporator_report import assess, vessel_heights
    from trackingbox.fmu import read_info
    from trackingbox.tracking.runtime import track

    case, spec, _, truth = short_case
    res = track(spec, out_dir=tmp_path_factory.mktemp("evtrack") / "track", window="validation")
    nrmse = {tag: (v.nrmse_untracked, v.nrmse_tracked) for tag, v in res.variables.items()
             if tag in {p.variable for p in spec.pairs}}
    result = assess(spec, res.csv, truth, nrmse=nrmse, heights=vessel_heights(read_info(spec.twin)),
                    settle=4 * 3600.0)
    return res, result


@pytest.mark.slow
@pytest.mark.compile
def test_tracking_holds_through_the_stoppage_and_closes_the_heat_transfer_offset(short_case, tracked) -> None:
    _, spec, _, _ = short_case
    res, result = tracked
    df = pd.read_csv(res.csv)
    t = df["time"].to_numpy(float)
    # parameters frozen while the feed is stopped (the stoppage we imposed), and no bump at the restart
    held = (t >= STOP.start + STOP.ramp_down + 60.0) & (t <= STOP.restart)
    for p in spec.pairs:
        col = df[f"parameter:{p.parameter}"].to_numpy(float)
        assert np.ptp(col[held]) == 0.0, p.parameter
        lo, hi = next((q.min, q.max) for q in spec.parameters if q.name == p.parameter)
        assert np.all((col >= lo) & (col <= hi))
    # the source's failure case must not happen: the twin's levels follow the measured ones through the
    # stoppage, and its temperatures do not jump
    window = (t >= STOP.start) & (t <= STOP.end + 1800.0)
    for st in spec.states:
        err = np.abs(df[f"tracked:{st.tag}"] - df[f"measured:{st.tag}"]).to_numpy(float)[window]
        assert np.nanmax(err) < 0.05, st.tag
    for tag in ("TI-6111", "TI-6151"):
        if f"tracked:{tag}" in df.columns:
            assert np.nanmax(np.abs(np.diff(df[f"tracked:{tag}"].to_numpy(float)[window]))) < 1.0, tag
    # no twin level leaves its vessel; the tracked heat-transfer parameter stays in its bounds and
    # brings its tag to at most 30 % of the untracked NRMSE on the validation window
    assert result.levels_ok, result.levels
    assert result.fouling is not None and result.fouling.within_bounds
    heat_tag = result.heat_transfer_pair[0]
    assert result.nrmse[heat_tag][2] <= 0.3, result.nrmse


@pytest.mark.slow
@pytest.mark.compile
@pytest.mark.xfail(strict=True, reason=(
    "measured on this case (seed 1): after the 4 h settle the tracked effect.Rf is 3.5e-4 m2.K/W on average "
    "against the plant's 2.2e-4 (truth.json), 21 % of the bound range too high on average, 61 % at most "
    "(38 % inside the stoppage): the tracker does not yet follow the plant's fouling within 10 %"))
def test_tracked_fouling_follows_the_plants_truth_within_10_percent_after_settling(tracked) -> None:
    _, result = tracked
    f = result.fouling
    assert f is not None and f.parameter == "effect.Rf"
    # |tracked - truth| / (bound range) from 4 h on, and inside the stoppage: the bench's done criterion
    assert f.max_error <= 0.1, f
    assert np.isnan(f.max_error_stoppages) or f.max_error_stoppages <= 0.1, f
    assert f.passed


@pytest.mark.parametrize("argv, message", [
    (["--days", "0"], "argument --days: must be a finite number > 0"),
    (["--days", "1", "--hours", "2"], "give --days or --hours, not both"),
])
def test_bench_command_rejects_bad_periods(tmp_path, capsys, argv, message) -> None:
    from trackingbox.cli import main

    assert main(["bench", "evaporator", "--out", str(tmp_path / "case"), *argv]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "case").exists()
