"""The budget of ``diagnose``: a refinement on a coarse grid, the linearised screen of compiled entries, timings.

Expectations come from outside the code under test: the plant's own parameter
value for the estimate, and the full nonlinear estimation of the patched twin
(:func:`trackingbox.diagnose.fit.fit_candidate`) for the linearised screen.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _fixtures_estimation import plant_data, write_case
from trackingbox.estimation import Objective, estimate, load_windows, problem_from_spec
from trackingbox.spec import load_spec

TRUE_KHT = 1250.0


def test_refinement_on_a_coarse_grid_finds_the_plant_value_and_reports_the_full_grid(
        hx_fmu: Path, tmp_path: Path) -> None:
    table = plant_data(hx_fmu, TRUE_KHT, noise=0.1, seed=3)
    spec = load_spec(write_case(tmp_path, hx_fmu, table, start=1000.0, lo=600.0, hi=1400.0))
    coarse = estimate(spec, maxiter=0, refine_grid=60.0)
    full = estimate(spec, maxiter=0)
    # the plant's value (0.1 K noise on a 2 h training window: well within 1 %)
    assert coarse.parameters["kht"] == pytest.approx(TRUE_KHT, rel=0.01)
    assert coarse.parameters["kht"] == pytest.approx(full.parameters["kht"], rel=0.005)
    # the reported training NRMSE is the full grid's, at the coarse estimate
    problem = problem_from_spec(spec)
    training, _ = load_windows(spec, warmup=problem.warmup)
    expected = Objective(problem, training).nrmse(np.array([coarse.parameters["kht"]]))
    assert coarse.training_nrmse["TI-1"] == pytest.approx(expected["TI-1"], rel=1e-9)
    # a grid of the sample time or finer is the full grid: the same result as without it
    same = estimate(spec, maxiter=0, refine_grid=10.0)
    assert same.parameters == full.parameters


@pytest.mark.compile
@pytest.mark.slow
def test_linearised_screen_of_a_compiled_entry_agrees_with_its_full_fit(hx_heat_loss_case, tmp_path):
    """Heat loss hidden on the heat-exchanger bench: the one-compile linear screen and the estimation agree."""
    from trackingbox.diagnose import library
    from trackingbox.diagnose.fit import FitBudget, fit_candidate, screen_compiled
    from trackingbox.diagnose.residuals import where

    spec = load_spec(hx_heat_loss_case.directory / "spec.toml")
    found = where(spec, estimate_options={"maxiter": 0, "refine_grid": 60.0})
    effect = library.load_effects(())["heat-loss"]
    screened = screen_compiled(spec, found, effect, "hx", tmp_path)
    assert screened.fit is None and screened.stage == "screen"
    fitted = fit_candidate(spec, found, effect, "hx", tmp_path, screened=screened,
                           budget=FitBudget(refine_iterations=8, grid=60.0))
    ua_screen, ua_fit = screened.values["UA"], fitted.values["UA"]
    assert ua_fit > 0 and ua_screen == pytest.approx(ua_fit, rel=0.2)
    assert screened.delta_bic > 10 and fitted.delta_bic > 10
    assert screened.delta_bic == pytest.approx(fitted.delta_bic, rel=0.3)
    # one FMU per effect and target: the fit reused the screen's compile
    assert len(list(tmp_path.glob("heat-loss-hx/*.fmu"))) == 1


def test_phase_clock_adds_wall_and_cpu_per_phase(monkeypatch) -> None:
    from trackingbox.diagnose import stage

    ticks = iter([(0.0, 0.0), (2.0, 1.5), (2.0, 1.5), (5.0, 2.0), (5.0, 2.0), (6.0, 2.25)])
    monkeypatch.setattr(stage._Clock, "_now", staticmethod(lambda: next(ticks)))
    clock = stage._Clock()
    clock.start("null")
    clock.start("screen")
    clock.start("null")
    clock.stop()
    clock.stop()  # a second stop adds nothing
    assert {k: (v.wall, v.cpu) for k, v in clock.phases.items()} == {"null": (3.0, 1.75), "screen": (3.0, 0.5)}
    assert clock.phases["null"].to_json() == {"wall": 3.0, "cpu": 1.75}


def test_patched_fmu_cache_key_follows_the_model_not_the_start_values(tmp_path) -> None:
    # a reused work folder must not hand back an FMU built from an older entry or twin source;
    # start values are tunable parameters and must not force a recompile
    from types import SimpleNamespace as NS

    from trackingbox.diagnose.fit import _compile_key

    (tmp_path / "P").mkdir()
    twin = tmp_path / "P" / "Twin.mo"
    twin.write_text("model Twin\n  Real x(start = 1);\nequation\n  der(x) = -x;\nend Twin;\n")
    spec = NS(source=NS(path=tmp_path / "P"))
    patch = NS(model="P.TwinDiagnosed", source="model TwinDiagnosed\n  extends Twin;\nend TwinDiagnosed;\n")
    key = _compile_key(spec, patch)
    assert _compile_key(spec, NS(model=patch.model, source=patch.source)) == key
    assert _compile_key(spec, NS(model=patch.model, source=patch.source + "// edited\n")) != key
    twin.write_text(twin.read_text().replace("-x", "-2*x"))
    assert _compile_key(spec, patch) != key


def test_runs_spread_over_workers_give_the_serial_series_and_jacobian(hx_fmu: Path, tmp_path: Path) -> None:
    """The null's series and output Jacobian from two worker processes equal the serial forward differences.

    The expectation is the serial implementation (``output_jacobian``, one run after the other in
    this process); the runs are deterministic, so the numbers must agree exactly, and the workers
    must really have run (their CPU time is this process's children's after the pool is joined).
    """
    import os

    from trackingbox.diagnose.parallel import pool
    from trackingbox.diagnose.residuals import output_jacobian, series_and_jacobian, window_series
    from trackingbox.estimation import close_models

    table = plant_data(hx_fmu, TRUE_KHT, hours=2.0, noise=0.1, seed=5)
    spec = load_spec(write_case(tmp_path, hx_fmu, table, training=(0.0, 3600.0), validation=(3600.0, 7200.0)))
    problem = problem_from_spec(spec)
    windows = load_windows(spec, warmup=problem.warmup)
    x = np.array([1100.0])
    try:
        serial = [window_series(problem, w, x, spec.inputs) for w in windows]
        serial_jac = [output_jacobian(problem, w, x, spec.inputs, s) for w, s in zip(windows, serial)]
    finally:
        close_models()
    children = os.times().children_user
    with pool(2):
        series, jac = series_and_jacobian(problem, windows, x, spec.inputs)
    assert os.times().children_user > children
    for s, s0, j, j0 in zip(series, serial, jac, serial_jac):
        np.testing.assert_array_equal(s.time, s0.time)
        assert set(j) == set(j0) == {"TI-1"}
        np.testing.assert_array_equal(s.simulated["TI-1"], s0.simulated["TI-1"])
        np.testing.assert_array_equal(j["TI-1"], j0["TI-1"])
        assert j["TI-1"].shape == (s.time.size, 1) and np.any(j["TI-1"] != 0.0)
