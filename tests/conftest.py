"""Shared fixtures: compile each Modelica class at most once per test run."""
from __future__ import annotations

import shutil
import threading
from pathlib import Path

import pytest

from trackingbox.compiler import compile_model, library_path, omc_available


class FMUCache:
    """Compile classes of the shipped library on first use; hand out the FMU path after."""

    def __init__(self, root: Path):
        self.root = root
        self._lock = threading.Lock()
        self._done: dict[str, Path] = {}

    def __call__(self, model: str) -> Path:
        with self._lock:
            if model not in self._done:
                out = self.root / f"{model}.fmu"
                compile_model(library_path(), model, backend="embedded", output=out)
                self._done[model] = out
            return self._done[model]


@pytest.fixture(scope="session")
def fmu_cache(tmp_path_factory: pytest.TempPathFactory) -> FMUCache:
    """``fmu_cache("TrackingBox.Benches.HeatExchanger.Twin")`` → path of its FMU (embedded backend)."""
    return FMUCache(tmp_path_factory.mktemp("fmus"))


@pytest.fixture(scope="session")
def library() -> Path:
    return library_path()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
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
