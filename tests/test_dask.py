"""The parallel stages on a Dask cluster give what the serial and process-pool paths give.

One ``LocalCluster`` of two single-threaded worker processes on 127.0.0.1 serves
the whole module (started once per session). The tests compare the Dask path
with the other executors, which run the same tasks elsewhere: the step tests'
gain matrix bit for bit against the serial path, Sobol indices likewise, an estimate against the
process pool's (differential evolution with the same generation-wise updates),
the diagnosis' parallel runs against the serial ones, and each worker opens an
FMU once however many tasks it runs.
"""
from __future__ import annotations

import shutil
import socket
from pathlib import Path

import numpy as np
import pytest

from trackingbox.analysis import executor
from trackingbox.analysis.executor import make_executor
from trackingbox.simulation import models
from trackingbox.simulation.models import cached_model, model_opens
from trackingbox.errors import AnalysisError

HX = "TrackingBox.Benches.HeatExchanger"


@pytest.fixture(scope="session")
def dask_cluster():
    """A local Dask cluster: 2 worker processes, 1 thread each, on 127.0.0.1 (HTTP on a free local port)."""
    from dask.distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0")
    try:
        yield cluster
    finally:
        cluster.close()


@pytest.fixture(scope="module")
def hx_case(fmu_cache, tmp_path_factory):
    """The heat-exchanger bench case (2 h of data) around the session's compiled plant and twin."""
    from trackingbox.benches import make_bench

    out = tmp_path_factory.mktemp("dask-hx") / "case"
    make_bench("heat-exchanger", out, seed=0, hours=2.0,
               plant_fmu=fmu_cache(f"{HX}.Plant"), twin_fmu=fmu_cache(f"{HX}.Twin"))
    return out / "spec.toml"


def _opens_per_worker(cluster, fmu: Path) -> dict[str, int]:
    from dask.distributed import Client

    key = str(Path(fmu).resolve())
    with Client(cluster) as client:
        return {worker: counts.get(key, 0) for worker, counts in client.run(model_opens).items()}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.compile
def test_step_tests_on_dask_give_the_serial_gain_matrix_bit_for_bit(hx_case, dask_cluster):
    from trackingbox.analysis.pair_stage import PairSettings, pair
    from trackingbox.spec import load_spec

    spec = load_spec(hx_case)
    quick = dict(data_checks=False, second_point="none")
    serial = pair(spec, PairSettings(workers=1, **quick))
    before = _opens_per_worker(dask_cluster, spec.twin)
    dask = pair(spec, PairSettings(scheduler=dask_cluster.scheduler_address, **quick))
    after = _opens_per_worker(dask_cluster, spec.twin)

    a, b = serial.steptest, dask.steptest
    assert a.variables == b.variables and a.parameters == b.parameters
    # the counter-flow exchanger's physics (as in test_pairing): more kht cools the hot outlet and
    # warms the cold one, so the matrix compared is a real one
    gains = dict(zip(a.variables, a.gains[:, a.parameters.index("hx.kht")]))
    assert gains["TI-102"] < 0 < gains["TI-202"]
    for name in ("gains", "gains_up", "gains_down", "baseline", "asymmetry", "time_constants"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert [(p.variable, p.parameter) for p in serial.pairing.pairs] == \
        [(p.variable, p.parameter) for p in dask.pairing.pairs]
    # each worker extracted and instantiated the twin at most once for all of the runs
    opened = {w: after[w] - before.get(w, 0) for w in after}
    assert b.runs > len(after) and all(n <= 1 for n in opened.values()), (b.runs, opened)
    assert sum(after.values()) <= len(after)


def test_sobol_runs_on_dask_give_the_serial_indices(step_fmu, dask_cluster):
    # the step-test twin of test_steptest with its integrator frozen: y1 = (1.5 a + z + 0.5 b) / 0.9, so a
    # explains 2.25 / 3.25 of y1's variance and b the rest, and b most of y2's (test_sobol's hand variances)
    from dask.distributed import Client

    from trackingbox.analysis.executor import DaskExecutor
    from trackingbox.analysis.sobol import sobol_indices
    from trackingbox.analysis.steptest import StepSettings, make_problem

    prob = make_problem(step_fmu, outputs={"Y1": "y1", "Y2": "y2"},
                        parameters=[("a", 1.0, 0.5, 1.5), ("b", 2.0, 1.0, 3.0)],
                        operating={"u": 1.5}, ranges={"Y1": 1.0, "Y2": 1.0}, freeze={"hold": 1.0})
    settings = StepSettings(freeze=(("hold", 1.0),), interval=1.0, window=50.0, tolerance=1e-6, max_time=2000.0)
    serial = sobol_indices(prob, settings, n=8)
    ex = DaskExecutor(Client(dask_cluster.scheduler_address))
    try:
        dask = sobol_indices(prob, settings, n=8, executor=ex)
    finally:
        ex.shutdown()
    assert dask.runs == serial.runs == 8 * 4
    np.testing.assert_array_equal(dask.first, serial.first)
    np.testing.assert_array_equal(dask.total, serial.total)
    assert dask.total[0, 0] > dask.total[0, 1] and dask.total[1, 1] > dask.total[1, 0]  # n = 8: coarse


def test_estimate_on_dask_gives_the_process_pool_estimate(hx_fmu, tmp_path, dask_cluster):
    from _fixtures_estimation import plant_data, write_case

    from trackingbox.estimation import estimate
    from trackingbox.spec import load_spec

    spec = load_spec(write_case(tmp_path / "case", hx_fmu, plant_data(hx_fmu, 910.0, hours=4.0)))
    # one generation of 5 and two fd refinement iterations: the pool's map serves both stages
    budget = dict(seed=0, maxiter=1, popsize=5, refine_iterations=2, jacobian="fd", warmup=1800.0)
    pooled = estimate(spec, workers=2, **budget)
    dask = estimate(spec, scheduler=dask_cluster.scheduler_address, **budget)
    assert dask.parameters == pooled.parameters
    assert dask.training_nrmse == pooled.training_nrmse
    assert dask.evaluations == pooled.evaluations and dask.history == pooled.history
    # and it is an estimate: the plant's kht is 910 (range 600..1400)
    assert dask.parameters["kht"] == pytest.approx(910.0, abs=20.0)
    # the twin (the case's copy) opened once per worker that ran an evaluation
    opens = _opens_per_worker(dask_cluster, spec.twin)
    assert 1 <= sum(opens.values()) <= 2 and all(n <= 1 for n in opens.values()), opens


def test_diagnosis_runs_on_dask_give_the_serial_series_and_jacobian(hx_fmu, tmp_path, dask_cluster):
    # the null model's series and output Jacobian (1 + n runs per window) as jobs on the cluster,
    # against the serial forward differences run one after the other in this process
    from _fixtures_estimation import plant_data, write_case

    from trackingbox.diagnose.parallel import pool
    from trackingbox.diagnose.residuals import output_jacobian, series_and_jacobian, window_series
    from trackingbox.estimation import close_models, load_windows, problem_from_spec
    from trackingbox.spec import load_spec

    table = plant_data(hx_fmu, 1250.0, hours=2.0, noise=0.1, seed=5)
    spec = load_spec(write_case(tmp_path, hx_fmu, table, training=(0.0, 3600.0), validation=(3600.0, 7200.0)))
    problem = problem_from_spec(spec, warmup=1800.0)
    windows = load_windows(spec, warmup=problem.warmup)
    x = np.array([1100.0])
    try:
        serial = [window_series(problem, w, x, spec.inputs) for w in windows]
        serial_jac = [output_jacobian(problem, w, x, spec.inputs, s) for w, s in zip(windows, serial)]
    finally:
        close_models()
    before = _opens_per_worker(dask_cluster, spec.twin)
    with pool(2, dask_cluster.scheduler_address):
        series, jac = series_and_jacobian(problem, windows, x, spec.inputs)
    opened = _opens_per_worker(dask_cluster, spec.twin)
    assert 1 <= sum(opened.values()) - sum(before.values()) <= 2  # the jobs ran on the workers
    for s, s0, j, j0 in zip(series, serial, jac, serial_jac):
        np.testing.assert_array_equal(s.simulated["TI-1"], s0.simulated["TI-1"])
        np.testing.assert_array_equal(j["TI-1"], j0["TI-1"])
        assert np.any(j["TI-1"] != 0.0)


def test_cached_model_is_keyed_by_content(hx_fmu, step_fmu, tmp_path):
    # one instance per path and content: asking again reuses it; a rewritten file is opened afresh
    path = tmp_path / "twin.fmu"
    shutil.copy(hx_fmu, path)
    first = cached_model(path)
    assert cached_model(path) is first
    assert model_opens()[str(path.resolve())] == 1
    shutil.copy(step_fmu, path)
    second = cached_model(path)
    assert second is not first
    assert "kht" in {v.name for v in first.info.variables}
    assert "kht" not in {v.name for v in second.info.variables}
    assert model_opens()[str(path.resolve())] == 2
    models.clear_model_cache()


def test_unreachable_scheduler_is_a_clear_error(hx_case, capsys, monkeypatch):
    from trackingbox.cli import main

    monkeypatch.setattr(executor, "CONNECT_TIMEOUT", 2.0)
    address = f"tcp://127.0.0.1:{_free_port()}"
    with pytest.raises(AnalysisError, match="cannot connect to a Dask scheduler"):
        make_executor(address)
    code = main(["pair", str(hx_case), "--no-write", "--no-data-checks", "--second-point", "none",
                 "--scheduler", address])
    err = capsys.readouterr().err
    assert code == 2
    assert f"error: --scheduler {address}: cannot connect to a Dask scheduler there within 2 s" in err
    # an address without a port is refused before any work
    assert main(["pair", str(hx_case), "--no-write", "--scheduler", "127.0.0.1"]) == 2
    assert "expected 'local' or a Dask scheduler address tcp://HOST:PORT" in capsys.readouterr().err


def test_local_scheduler_starts_and_stops_its_own_cluster():
    with make_executor("local", 2) as ex:
        assert ex.workers == 2
        assert list(ex.map(pow, [2, 3], [10, 2])) == [1024, 9]
        cluster = ex.cluster
    assert cluster.status.name == "closed"
    with pytest.raises(AnalysisError, match="--workers must be an integer >= 1"):
        make_executor("local", 0)
