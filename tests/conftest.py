"""Shared fixtures: compile each Modelica class and build each small test FMU at most once per run.

``scripts/test`` runs the suite in several worker processes (pytest-xdist); the bench FMUs
(``fmu_cache``, ``train_fmu``) are then compiled once for all of them, into the run's common
temporary folder under a file lock (:func:`built_once`), so a bench is still compiled once per run.

The CasADi-made FMUs (``_fixtures_casadi.build_casadi_fmu``) are built in a child
process inside a session temporary directory, never by changing the test
process's working directory.
"""
from __future__ import annotations

import fcntl
import os
import shutil
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from trackingbox.compiler import compile_model, library_path, omc_available


def run_folder(factory: pytest.TempPathFactory, name: str) -> Path:
    """A folder every worker process of this run shares (the workers' common temporary parent under
    pytest-xdist), or a fresh temporary folder when the suite runs in one process."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = factory.getbasetemp().parent / name
        root.mkdir(exist_ok=True)
        return root
    return factory.mktemp(name)


def built_once(root: Path, key: str, build: Callable[[Path], Path]) -> Path:
    """``build(folder)`` run once per *key* across the run's processes and threads; its path after.

    An exclusive ``flock`` on ``<key>.lock`` serialises the builders; ``<key>.done`` records the path
    once the build has returned, so a build that raised is tried again by the next caller."""
    done = root / f"{key}.done"
    with open(root / f"{key}.lock", "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        if done.exists():
            return Path(done.read_text())
        out = build(root / key)
        done.write_text(str(out))
        return out


class FMUCache:
    """Compile classes of the shipped library on first use; hand out the FMU path after."""

    def __init__(self, root: Path):
        self.root = root

    def __call__(self, model: str) -> Path:
        def build(folder: Path) -> Path:
            folder.mkdir(exist_ok=True)
            out = folder / f"{model}.fmu"
            compile_model(library_path(), model, backend="embedded", output=out)
            return out

        return built_once(self.root, model, build)


@pytest.fixture(scope="session")
def fmu_cache(tmp_path_factory: pytest.TempPathFactory) -> FMUCache:
    """``fmu_cache("TrackingBox.Benches.HeatExchanger.Twin")`` → path of its FMU (embedded backend)."""
    return FMUCache(run_folder(tmp_path_factory, "fmus"))


@pytest.fixture(scope="session")
def library() -> Path:
    return library_path()


@pytest.fixture(scope="session")
def step_fmu(tmp_path_factory: pytest.TempPathFactory) -> str:
    """The step-test twin of ``_fixtures_analysis`` (seven states, hold and correction inputs)."""
    from _fixtures_analysis import build_step_fmu

    return build_step_fmu(tmp_path_factory.mktemp("steptwin"))


@pytest.fixture(scope="session")
def first_order_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The first-order tracking twin of ``_fixtures_tracking`` (tunable ``k``, input ``u``, output ``y``)."""
    from _fixtures_tracking import make_first_order_fmu

    return make_first_order_fmu(tmp_path_factory.mktemp("hx1"))


@pytest.fixture(scope="session")
def tank_fmu(tmp_path_factory: pytest.TempPathFactory) -> Callable[[float], Path]:
    """``tank_fmu(leak)``: the first-order twin plus a tank (``_fixtures_tracking.make_tank_fmu``), built once per leak."""
    from _fixtures_tracking import make_tank_fmu

    built: dict[float, Path] = {}
    lock = threading.Lock()

    def get(leak: float) -> Path:
        with lock:
            if leak not in built:
                built[leak] = make_tank_fmu(tmp_path_factory.mktemp(f"tank-leak{leak:g}"), leak=leak)
            return built[leak]

    return get


@pytest.fixture(scope="session")
def hx_heat_loss_case(fmu_cache: FMUCache, tmp_path_factory: pytest.TempPathFactory) -> Any:
    """``bench heat-exchanger --hidden heat-loss`` over 4 h, seed 0 (its twin from :func:`fmu_cache`), written
    once per session: the diagnose tests' compiled-entry case (read only)."""
    from trackingbox.benches import make_bench

    return make_bench("heat-exchanger", tmp_path_factory.mktemp("hx-heat-loss") / "case", seed=0, hours=4.0,
                      twin_fmu=fmu_cache("TrackingBox.Benches.HeatExchanger.Twin"), hidden="heat-loss")


@pytest.fixture(scope="session")
def hx_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The first-order heat-exchanger FMU of ``_fixtures_estimation`` (parameter ``kht``)."""
    from _fixtures_estimation import build_fmu

    return build_fmu(tmp_path_factory.mktemp("hx1fmu"))


@pytest.fixture(scope="session")
def train_fmu(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    """``train_fmu(n, plant=None)`` / ``train_fmu(n, twin=True)``: the *n*-effect train's plant (default
    ``Plant``, or the full class name of a variant such as ``...EvaporatorTrain.Hidden.Clean``) or its twin,
    compiled once per session (``benches.evaporator_train.compile_train``)."""
    from trackingbox.benches.evaporator_train import compile_train, train_models

    root = run_folder(tmp_path_factory, "train-fmus")

    def get(n: int, plant: str | None = None, *, twin: bool = False) -> Path:
        what = "twin" if twin else "plant"
        key = f"{n}-{'twin' if twin else (plant or 'Plant')}"
        return built_once(root, key, lambda folder: compile_train(train_models(n, plant), what,
                                                                   folder / "build" / f"{what}.fmu"))

    return get


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--long", action="store_true",
                     help="run the tests marked long (scripts/bench_long passes it)")


LONG_REASON = ("a long end-to-end run, kept out of scripts/test to hold the suite inside CI's 25 minutes: "
               "scripts/bench_long runs it")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not config.getoption("--long"):
        for item in items:
            if "long" in item.keywords:
                item.add_marker(pytest.mark.skip(reason=LONG_REASON))
    if omc_available():
        return
    reason = ("omc (OpenModelica) is not on PATH: it cannot be installed from Debian's or PyPI's "
              "packages; the OpenModelica backend is tested where omc is installed")
    for item in items:
        if "openmodelica" in item.keywords:
            item.add_marker(pytest.mark.skip(reason=reason))


def copy_tree(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst
