"""Gray-box parameter estimation on a small first-order heat-exchanger FMU with synthetic data.

Independent expectations: the true parameter the data were made with, the
statistical precision a least-squares fit can reach with the added noise, the
noise floor of the NRMSE, hand-counted masked samples, and the bounds.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from _fixtures_estimation import plant_data, steady_state, write_case
from trackingbox.errors import DataError, SpecError
from trackingbox.estimation import EstimationResult, estimate, load_windows, nrmse, write_starts
from trackingbox.spec import load_spec

TRUE_KHT = 900.0
NOISE = 0.1  # K, standard deviation of the measurement noise

pytestmark = pytest.mark.compile


@pytest.fixture(scope="module")
def fmu(hx_fmu: Path) -> Path:
    return hx_fmu  # built once per session (conftest)


@pytest.fixture(scope="module")
def clean_case(fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, EstimationResult]:
    table = plant_data(fmu, TRUE_KHT, noise=NOISE, seed=1)
    spec = write_case(tmp_path_factory.mktemp("clean"), fmu, table)
    return spec, estimate(load_spec(spec), seed=0, maxiter=5, popsize=10)


def _kht_standard_error(fmu: Path, spec_path: Path) -> float:
    """Standard error of a least-squares kht estimate: sigma / ||dy/dkht|| over the training samples."""
    from trackingbox.fmu import FMUModel

    table = load_windows(load_spec(spec_path))[0]
    u = {name: values for name, values in table.inputs.items()}
    import pandas as pd

    pre = 20000.0
    frame = pd.DataFrame({"time": np.concatenate(([0.0], pre + table.time)),
                          **{k: np.concatenate(([v[0]], v)) for k, v in u.items()}})
    model = FMUModel(fmu)
    try:
        ys = [np.interp(pre + table.time, *model.simulate(stop_time=pre + table.time[-1], output_interval=10.0,
                                                          inputs=frame, parameters={"kht": k, "A": 2.0},
                                                          outputs=["T_out"]).to_numpy().T)
              for k in (TRUE_KHT - 5.0, TRUE_KHT + 5.0)]
    finally:
        model.close()
    sensitivity = (ys[1] - ys[0]) / 10.0
    return NOISE / float(np.sqrt(np.sum(sensitivity ** 2)))


def test_nrmse_hand_computed() -> None:
    # errors 0, -1, -1 -> RMSE sqrt(2/3); measured range 5 - 1 = 4
    assert nrmse([1.0, 2.0, 4.0], [1.0, 3.0, 5.0]) == pytest.approx(math.sqrt(2.0 / 3.0) / 4.0)
    # NaN measurements are ignored, also for the range
    assert nrmse([1.0, 99.0, 4.0], [1.0, np.nan, 5.0]) == pytest.approx(math.sqrt(0.5) / 4.0)


def test_plant_data_start_settled(fmu: Path) -> None:
    # the fixture's plant starts at the hand-solved steady state of the first inputs
    table = plant_data(fmu, TRUE_KHT, noise=0.0)
    expected = steady_state(table["FI-1"][0], table["TI-0"][0], TRUE_KHT)
    assert table["TI-1"][0] == pytest.approx(expected, abs=0.05)


def test_recovers_true_parameter_within_noise(fmu: Path, clean_case: tuple[Path, EstimationResult]) -> None:
    spec_path, result = clean_case
    se = _kht_standard_error(fmu, spec_path)
    # 4 standard errors of the noise-limited estimate, and in any case within 1 %
    assert abs(result.parameters["kht"] - TRUE_KHT) <= max(4.0 * se, 1e-3 * TRUE_KHT)
    assert abs(result.parameters["kht"] - TRUE_KHT) <= 0.01 * TRUE_KHT
    # at the estimate only the noise is left: NRMSE ~ sigma / range of the measured tag
    table = load_windows(load_spec(spec_path))[0].measured["TI-1"]
    floor = NOISE / (np.nanmax(table) - np.nanmin(table))
    assert 0.8 * floor <= result.training_nrmse["TI-1"] <= 1.2 * floor
    # the start value kht = 1000 fits clearly worse on the validation window
    assert result.validation_nrmse["TI-1"] < 0.2 * result.validation_nrmse_initial["TI-1"]
    assert result.evaluations > 0 and result.seconds > 0
    assert list(result.history) == sorted(result.history, reverse=True)  # best-so-far never rises


def test_masked_samples_do_not_change_the_estimate(fmu: Path, tmp_path: Path) -> None:
    # the plant stops (flow 0) from 2400 s to 3300 s; the stoppage rule masks flow < 0.05 plus 300 s
    stop = (2400.0, 3300.0)
    table = plant_data(fmu, TRUE_KHT, noise=NOISE, seed=2, stoppage=stop)
    # and the outlet sensor is missing from 5000 s to 5590 s (60 rows)
    missing = (table["time"] >= 5000.0) & (table["time"] < 5600.0)
    table.loc[missing, "TI-1"] = np.nan
    rules = '\n[data]\nstoppage = { tag = "FI-1", below = 0.05, settle = 300.0 }\nmax_gap = 30.0\n'
    spec_a = write_case(tmp_path / "a", fmu, table, data=rules)

    # hand count: training grid 0..7190 s (720 points); stoppage 2400..3290 (90) + settle to 3590 (30);
    # missing outlet 5000..5590 (60): 720 - 90 - 30 - 60 = 540 samples in the cost
    training, validation = load_windows(load_spec(spec_a))
    assert training.valid_counts() == {"TI-1": 540}
    # the validation window [7200, 14400) s is led in by the 720 samples before it, which are not scored
    assert validation.lead == 720 and validation.time[0] == 0.0
    assert validation.valid_counts() == {"TI-1": 720}
    assert np.isnan(training.measured["TI-1"][training.time == 3580.0]).all()
    assert np.isfinite(training.measured["TI-1"][training.time == 3600.0]).all()

    # corrupt the outlet temperature inside the stoppage and its settle time: +30 K
    corrupt = table.copy()
    inside = (corrupt["time"] >= stop[0]) & (corrupt["time"] < stop[1] + 300.0)
    corrupt.loc[inside, "TI-1"] += 30.0
    spec_b = write_case(tmp_path / "b", fmu, corrupt, data=rules)
    a = estimate(load_spec(spec_a), seed=0, maxiter=3, popsize=10)
    b = estimate(load_spec(spec_b), seed=0, maxiter=3, popsize=10)
    assert b.parameters["kht"] == pytest.approx(a.parameters["kht"], rel=1e-9)
    assert abs(a.parameters["kht"] - TRUE_KHT) <= 0.01 * TRUE_KHT
    # without the stoppage rule the same corruption does move the estimate (so the check above can fail)
    spec_c = write_case(tmp_path / "c", fmu, corrupt, data="\n[data]\nmax_gap = 30.0\n")
    c = estimate(load_spec(spec_c), seed=0, maxiter=3, popsize=10)
    assert abs(c.parameters["kht"] - a.parameters["kht"]) > 0.01 * TRUE_KHT


def test_bounds_respected_and_checkpoint(fmu: Path, tmp_path: Path) -> None:
    # true value 900 lies below the bounds [950, 1200]: the estimate must stop at the lower bound
    table = plant_data(fmu, TRUE_KHT, noise=NOISE, seed=3)
    spec = write_case(tmp_path, fmu, table, start=1100.0, lo=950.0, hi=1200.0)
    seen: list[tuple[str, int]] = []
    result = estimate(load_spec(spec), seed=1, maxiter=3, popsize=10, checkpoint=tmp_path / "ckpt.json",
                      progress=lambda stage, i, n, best: seen.append((stage, i)))
    assert 950.0 <= result.parameters["kht"] <= 950.0 * (1 + 1e-6)
    assert seen[0] == ("global", 1) and seen[-1] == ("local", 1)
    saved = json.loads((tmp_path / "ckpt.json").read_text())
    assert saved["stage"] == "done"
    assert saved["parameters"]["kht"] == pytest.approx(result.parameters["kht"])


def test_too_little_data(fmu: Path, tmp_path: Path) -> None:
    table = plant_data(fmu, TRUE_KHT, hours=1.0)
    # 100 s of training window = 10 samples on the 10 s grid
    spec = write_case(tmp_path, fmu, table, training=(0.0, 100.0), validation=(100.0, 3600.0))
    with pytest.raises(DataError, match=r"'TI-1' has 10 valid samples in the training window.*at least 20"):
        estimate(load_spec(spec), maxiter=1)


def test_communication_loss_of_every_input_is_held_and_masked(fmu: Path, tmp_path: Path) -> None:
    # a communication loss empties both inputs at 720-3070 s (the evaporator case's 720-3070 s loss);
    # the plant ran on its real, moving inputs all along and the outlet temperature was still logged
    table = plant_data(fmu, TRUE_KHT, noise=NOISE, seed=4)
    gap = (table["time"] >= 720.0) & (table["time"] <= 3070.0)
    table.loc[gap, ["FI-1", "TI-0"]] = np.nan
    rules = '\n[data]\nstoppage = { tag = "FI-1", below = 0.05, settle = 300.0 }\nmax_gap = 30.0\n'
    spec_a = write_case(tmp_path / "a", fmu, table, data=rules)
    training, _ = load_windows(load_spec(spec_a))
    # the twin's inputs hold the last good value, the sample at 710 s, through the gap
    at = (training.time >= 720.0) & (training.time <= 3070.0)
    last = table.loc[table["time"] == 710.0]
    assert (training.inputs["m_flow"][at] == float(last["FI-1"].iloc[0])).all()
    assert (training.inputs["T_in"][at] == float(last["TI-0"].iloc[0])).all()
    # hand count: training grid 0..7190 s (720 points); the gap 720..3070 s (236 points) and the
    # stoppage rule's 300 s settle after it (3080..3370 s, 30 points) are not scored: 720 - 266
    assert training.valid_counts() == {"TI-1": 454}
    assert np.isnan(training.measured["TI-1"][training.time == 3370.0]).all()
    assert np.isfinite(training.measured["TI-1"][training.time == 3380.0]).all()
    # the estimate is the plant's, and the outlet readings in the gap do not enter it: +30 K there
    # changes nothing
    a = estimate(load_spec(spec_a), seed=0, maxiter=3, popsize=10)
    assert abs(a.parameters["kht"] - TRUE_KHT) <= 0.01 * TRUE_KHT
    corrupt = table.copy()
    corrupt.loc[(corrupt["time"] >= 720.0) & (corrupt["time"] < 3370.0), "TI-1"] += 30.0
    b = estimate(load_spec(write_case(tmp_path / "b", fmu, corrupt, data=rules)), seed=0, maxiter=3, popsize=10)
    assert b.parameters["kht"] == pytest.approx(a.parameters["kht"], rel=1e-9)


def test_input_with_no_value_at_all_is_refused(fmu: Path, tmp_path: Path) -> None:
    table = plant_data(fmu, TRUE_KHT, hours=1.0)
    table["FI-1"] = np.nan
    spec = write_case(tmp_path, fmu, table, training=(0.0, 1800.0), validation=(1800.0, 3600.0),
                      data="\n[data]\nmax_gap = 60.0\n")
    # the data reader refuses a tag with no value at all before estimation looks at inputs
    with pytest.raises(DataError, match=r"measurements.csv has no value at all .*'FI-1'"):
        estimate(load_spec(spec), maxiter=1)


def test_unknown_parameter_did_you_mean(fmu: Path, tmp_path: Path) -> None:
    table = plant_data(fmu, TRUE_KHT, hours=1.0)
    spec = write_case(tmp_path, fmu, table, name="khtt", training=(0.0, 1800.0), validation=(1800.0, 3600.0))
    with pytest.raises(SpecError, match=r"unknown parameter 'khtt'.*did you mean 'kht'"):
        estimate(load_spec(spec), maxiter=1)


def test_write_starts_keeps_comments(fmu: Path, tmp_path: Path) -> None:
    table = plant_data(fmu, TRUE_KHT, hours=1.0)
    spec_path = write_case(tmp_path, fmu, table, training=(0.0, 1800.0), validation=(1800.0, 3600.0))
    before = spec_path.read_text()
    spec = write_starts(spec_path, {"kht": 912.5})
    after = spec_path.read_text()
    assert spec.parameter("kht").start == 912.5
    assert load_spec(spec_path).parameter("kht").start == 912.5
    assert "# heat-transfer coefficient" in after and after.startswith("# test spec")
    # only the start line changed
    changed = [(a, b) for a, b in zip(before.splitlines(), after.splitlines()) if a != b]
    assert changed == [("start = 1000.0", "start = 912.5")]
    with pytest.raises(SpecError, match="outside"):
        write_starts(spec_path, {"kht": 5000.0})


def test_estimate_command_json_report_write(fmu: Path, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    import argparse

    from trackingbox.commands import estimate as command

    table = plant_data(fmu, TRUE_KHT, noise=NOISE, seed=4, hours=2.0)
    spec_path = write_case(tmp_path / "case", fmu, table, training=(0.0, 3600.0), validation=(3600.0, 7200.0))
    parser = argparse.ArgumentParser()
    command.register(parser.add_subparsers())
    report = tmp_path / "report"
    args = parser.parse_args(["estimate", str(spec_path), "--json", "--report", str(report), "--maxiter", "3",
                              "--write"])
    assert args.func(args) == 0
    doc = json.loads(capsys.readouterr().out)  # exactly one JSON document on stdout
    assert set(doc) == {"parameters", "training", "validation", "evaluations", "seconds", "refinement", "warmup",
                        "identifiability", "uncertainty"}
    # the training window starts at the first sample: no history there, and the document says so
    assert doc["warmup"]["used"]["training"] == 0.0 and "shortened" in doc["warmup"]["note"]
    interval = doc["uncertainty"]["parameters"]["kht"]
    assert interval["lower"] < doc["parameters"]["kht"] < interval["upper"], interval
    # the CasADi-made twin provides directional derivatives; "auto" takes them unless its runs are native
    assert doc["refinement"]["jacobian"] == ("fd" if _runs_native(fmu) else "exact"), doc["refinement"]
    assert set(doc["validation"]) == {"nrmse", "nrmse_initial"}
    assert abs(doc["parameters"]["kht"] - TRUE_KHT) <= 0.01 * TRUE_KHT
    assert doc["validation"]["nrmse"]["TI-1"] < doc["validation"]["nrmse_initial"]["TI-1"]
    for name in ("fit_TI-1.png", "convergence.png", "parameters.md", "checkpoint.json", "result.json"):
        assert (report / name).stat().st_size > 0, name
    assert (report / "fit_TI-1.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| `kht` | 1000 |" in (report / "parameters.md").read_text()
    # --write: the estimate is now the start value
    assert load_spec(spec_path).parameter("kht").start == pytest.approx(doc["parameters"]["kht"])


# --------------------------------------------------------------------------- benches (Done criteria)


@pytest.fixture(scope="module")
def hx_fmus(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Heat-exchanger plant and twin FMUs, compiled once for the bench cases below."""
    from trackingbox.benches import make_bench

    case = make_bench("heat-exchanger", tmp_path_factory.mktemp("hx-compile"), seed=0, hours=0.5)
    return case.plant_fmu, case.twin_fmu


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "kht"), [(1, None), (2, 700.0), (3, 1300.0)])
def test_heat_exchanger_bench_recovers_kht(hx_fmus: tuple[Path, Path], tmp_path: Path, seed: int,
                                           kht: float | None) -> None:
    from trackingbox.benches import make_bench

    plant, twin = hx_fmus
    case = make_bench("heat-exchanger", tmp_path, seed=seed, overrides={"hx.kht": kht} if kht else None,
                      plant_fmu=plant, twin_fmu=twin)
    true = case.truth["hx.kht"]
    assert true == (kht if kht else 910.0)  # the plant's own value (method notes) unless --set
    result = estimate(load_spec(case.spec), seed=seed, maxiter=12)
    assert abs(result.parameters["hx.kht"] - true) <= 0.02 * true
    # every truth here is >= 9 % away from the start value 1000: the estimate must fit the held-out data better
    for tag, value in result.validation_nrmse.items():
        assert value < 0.5 * result.validation_nrmse_initial[tag]


# --------------------------------------------------------------------------- building blocks


def test_jacobian_points_stay_inside_bounds() -> None:
    from trackingbox.estimation import jacobian_points

    # steps are 1e-3 of each bound range; at an upper bound the step is taken backwards
    points, steps = jacobian_points([0.005, 1.1], [0.0001, 0.9], [0.01, 1.1])
    assert steps.tolist() == pytest.approx([0.0099e-3, -0.2e-3])
    np.testing.assert_allclose(points, [[0.005 + 0.0099e-3, 1.1], [0.005, 1.1 - 0.2e-3]], rtol=1e-12)
    assert np.all(points >= [0.0001, 0.9]) and np.all(points <= [0.01, 1.1])


def test_coarsen_keeps_the_window_start_and_averages_inputs() -> None:
    from trackingbox.estimation import WindowData, coarsen

    # 10 s grid, lead-in of 4 points before the window start at 40 s; stride 3
    time_s = np.arange(0.0, 120.0, 10.0)
    measured = np.where(time_s >= 40.0, time_s / 10.0, np.nan)
    w = WindowData("training", 40.0, 120.0, time_s, {"u": time_s / 10.0}, {"y": measured}, lead=4)
    c = coarsen(w, 3)
    # 4 % 3 = 1: points 1, 4, 7, 10 -> the window start (index 4) stays on the grid, one lead-in point
    assert c.time.tolist() == [10.0, 40.0, 70.0, 100.0]
    assert c.lead == 1 and np.isnan(c.measured["y"][0])
    assert c.measured["y"][1:].tolist() == [4.0, 7.0, 10.0]
    # centred means over 3 samples of u = 0, 1, ..., 11: (0+1+2)/3, (3+4+5)/3, ...
    assert c.inputs["u"].tolist() == pytest.approx([1.0, 4.0, 7.0, 10.0])


def test_default_budget_for_many_parameters() -> None:
    from trackingbox.estimation import DEFAULT_GLOBAL_EVALUATIONS, default_maxiter

    # one parameter: population 15, the full 30 generations; fourteen: population 28 in all
    assert default_maxiter(1) == 30
    assert 28 * (default_maxiter(14) + 1) <= DEFAULT_GLOBAL_EVALUATIONS


# --------------------------------------------------------------------------- heat-production bench


@pytest.mark.slow
def test_heat_production_short_window_finds_the_heat_transfer_coefficients(fmu_cache, tmp_path: Path) -> None:
    """Estimation on the heat-production bench, short: 4 h of data, the two heat-transfer coefficients.

    The full 24 h, fourteen-parameter check with the CLI's budget is a benchmark
    (``scripts/bench_heat_production``, exits non-zero when a criterion fails).
    Here the twelve hydraulic parameters are fixed at the plant's true values
    (``truth.json``) and only ``HU300.kht`` and ``HEX300.kht`` (seen directly by
    TI-310 / TI-301) are estimated from their start values (1050 and 1000, 5 % and
    8.7 % from the truth) with a small budget. Expected, from the plant's truth and
    not from our numbers: both in their bounds and within 4 % of the truth (closer
    than either start value), the estimate fits the training window at least as
    well as the truth does, and the held-out NRMSE of TI-301 and TI-310 halves.
    4 % and not the benchmark's 2 %: on a 2 h training window the twin's
    linearised pipe and pump curves bias the estimate (measured: HEX300.kht 895
    for 920, with a lower training NRMSE than at the truth, so the optimiser is
    not what limits it).
    """
    import dataclasses

    from trackingbox.benches import make_bench

    hp = "TrackingBox.Benches.HeatProduction"
    case = make_bench("heat-production", tmp_path / "hp", seed=0, hours=4.0,
                      plant_fmu=fmu_cache(f"{hp}.Plant"), twin_fmu=fmu_cache(f"{hp}.Twin"))
    spec = load_spec(case.spec)
    free = ("HU300.kht", "HEX300.kht")
    spec = dataclasses.replace(
        spec, parameters=tuple(p for p in spec.parameters if p.name in free),
        fixed={**spec.fixed, **{p.name: case.truth[p.name] for p in spec.parameters if p.name not in free}})
    for name in free:  # the start values are far enough from the truth for the test to mean something
        assert abs(spec.parameter(name).start - case.truth[name]) >= 0.04 * case.truth[name]
    result = estimate(spec, seed=0, workers=1, maxiter=6, refine_iterations=20)
    for name in free:
        p = spec.parameter(name)
        assert p.min <= result.parameters[name] <= p.max, name
        assert abs(result.parameters[name] - case.truth[name]) <= 0.04 * case.truth[name], \
            (name, result.parameters[name], case.truth[name])
    from trackingbox.estimation import Objective, problem_from_spec

    problem = problem_from_spec(spec)
    at_truth = Objective(problem, load_windows(spec)[0])(np.array([case.truth[n] for n in problem.names]))
    assert float(np.mean(list(result.training_nrmse.values()))) <= at_truth
    for tag in ("TI-301", "TI-310"):
        assert result.validation_nrmse[tag] <= 0.5 * result.validation_nrmse_initial[tag], tag


def _runs_native(fmu) -> bool:
    """Whether the twin's runs go through the native stepper (then ``jacobian="auto"`` takes fd)."""
    from trackingbox.estimation.objective import runs_native
    from trackingbox.simulation.models import cached_model as _model

    return runs_native(_model(fmu))
