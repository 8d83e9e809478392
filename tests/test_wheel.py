"""The package as a user gets it: a wheel built from the checkout, installed into a clean environment.

The editable install of ``scripts/_env.sh`` reads the checkout, so a module or data file
that the wheel leaves out goes unnoticed there (``trackingbox.report`` and
``trackingbox.testing`` were missing from the wheel and ``trackingbox track`` failed after
``pip install .``). Here the wheel is built from a copy of the checkout, checked against the
source folders (every module and data file there, no setuptools warning while building),
installed non-editable with its dependencies into a new virtual environment, and its console
scripts run from a folder outside the checkout: ``--version``, a compile of a bench model
from the installed library, and a one-hour heat-exchanger case through ``bench``, ``pair``,
``track`` and ``gen-trackingbox --compile``.

The dependencies come through pip's own configuration (index, ``--find-links``, its cache),
the same wheels ``scripts/test`` installed, so nothing is downloaded twice. The environment
is removed when the module ends (about 1 GB).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.wheel

#: a guard against a hung subprocess, not a timing assertion
HANG = 1800.0

#: what the build reads; everything else in the checkout (tests, docs, .venv, outputs) is left out
BUILD_INPUTS = ("pyproject.toml", "setup.py", "README.md", "pyside", "codegen", "modelica")

#: the source folders and the import name each is installed under (pyproject.toml's package-dir)
FOLDERS = {"pyside/trackingbox": "trackingbox", "codegen": "trackingbox/codegen", "modelica": "trackingbox/modelica"}

#: data files the package reads at run time (templates, effects, the Modelica library, the C stepper)
DATA = ("*.jinja", "effect.toml", "*.mo", "package.order", "*.c", "py.typed")


def _clean_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env.update(extra)
    return env


def _run(argv: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=HANG)


def _ok(proc: subprocess.CompletedProcess[str]) -> subprocess.CompletedProcess[str]:
    assert proc.returncode == 0, f"{proc.args} exited {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def _ignored(_folder: str, names: list[str]) -> set[str]:
    return {n for n in names if n == "__pycache__" or n.endswith((".pyc", ".egg-info"))}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """``pip wheel --no-deps`` of a copy of the build inputs; returns the wheel and the build's output."""
    tmp = tmp_path_factory.mktemp("wheel")
    source = tmp / "source"
    source.mkdir()
    for name in BUILD_INPUTS:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, source / name, ignore=_ignored)
        elif path.exists():
            shutil.copy2(path, source / name)
    proc = _ok(_run([sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "-w", str(tmp / "dist")],
                    cwd=tmp, env=_clean_env()))
    [wheel] = (tmp / "dist").glob("trackingbox-*.whl")
    return wheel, proc.stdout + proc.stderr


def test_the_wheel_builds_without_a_setuptools_warning(built: tuple[Path, str]) -> None:
    _, log = built
    # setuptools names its warnings by class (BuildBackendWarning, SetuptoolsDeprecationWarning ...);
    # pip's own "WARNING:" lines about the index configuration are not the build's
    warnings = sorted({m.group(0) for m in re.finditer(r"\b[A-Z]\w*Warning\b: [^\n]{0,100}", log)})
    assert warnings == []


def test_the_wheel_holds_every_module_and_data_file_of_the_source_folders(built: tuple[Path, str]) -> None:
    wheel, _ = built
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    expected = set()
    for folder, installed in FOLDERS.items():
        for path in (ROOT / folder).rglob("*"):
            if "__pycache__" in path.parts or not path.is_file():
                continue
            if path.suffix == ".py" or any(path.match(pattern) for pattern in DATA):
                expected.add(f"{installed}/{path.relative_to(ROOT / folder).as_posix()}")
    assert {"trackingbox/report/__init__.py", "trackingbox/testing/__init__.py"} <= expected
    assert sorted(expected - names) == []


@pytest.fixture(scope="module")
def installed(built: tuple[Path, str], tmp_path_factory: pytest.TempPathFactory):
    """A new virtual environment with the wheel installed (not editable) and its dependencies; its ``bin``."""
    wheel, _ = built
    where = tmp_path_factory.mktemp("venv")
    env_dir = where / "env"
    venv.EnvBuilder(with_pip=True, clear=True).create(env_dir)
    _ok(_run([str(env_dir / "bin" / "python"), "-m", "pip", "install", "--quiet", str(wheel)],
             cwd=where, env=_clean_env()))
    yield env_dir / "bin"
    shutil.rmtree(env_dir, ignore_errors=True)


@pytest.fixture
def outside(tmp_path: Path, installed: Path) -> dict[str, object]:
    """A working folder outside the checkout, and an environment where only the installed package is found."""
    assert ROOT not in tmp_path.resolve().parents
    # a fresh cache: the native stepper is built from the installed stepper.c, not found built already
    env = _clean_env(XDG_CACHE_HOME=str(tmp_path / "cache"), PATH=f"{installed}{os.pathsep}{os.environ['PATH']}")
    return {"cwd": tmp_path, "env": env}


def test_the_installed_package_is_the_one_imported(installed: Path, outside: dict) -> None:
    proc = _ok(_run([str(installed / "python"), "-c",
                     "import trackingbox, trackingbox.report, trackingbox.testing, trackingbox.codegen, "
                     "trackingbox.modelica; print(trackingbox.__file__)"], **outside))
    where = Path(proc.stdout.strip()).resolve()
    assert installed.parent.resolve() in where.parents and ROOT not in where.parents


def test_version_is_the_projects(installed: Path, outside: dict) -> None:
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    proc = _ok(_run([str(installed / "trackingbox"), "--version"], **outside))
    assert proc.stdout.strip() == f"trackingbox {version}"


def test_compile_of_a_bench_model_from_the_installed_library(installed: Path, outside: dict) -> None:
    proc = _ok(_run([str(installed / "python"), "-c",
                     "from trackingbox.compiler import library_path; print(library_path())"], **outside))
    library = Path(proc.stdout.strip())
    assert installed.parent.resolve() in library.resolve().parents
    cwd: Path = outside["cwd"]  # type: ignore[assignment]
    proc = _ok(_run([str(installed / "trackingbox"), "compile", str(library),
                     "--model", "TrackingBox.Benches.HeatExchanger.Twin", "-o", "twin.fmu", "--json"], **outside))
    assert json.loads(proc.stdout)["backend"] == "embedded"
    described = json.loads(_ok(_run([str(installed / "trackingbox"), "inspect", "twin.fmu", "--json"],
                                    **outside)).stdout)
    names = {v["name"]: v for v in described["variables"]}
    # the twin as the library declares it: the tunable heat-transfer coefficient with its bounds, both outlets
    assert (names["hx.kht"]["min"], names["hx.kht"]["max"]) == (500.0, 1500.0)
    assert {"ThOut", "TcOut"} <= {n for n, v in names.items() if v["causality"] == "output"}
    assert (cwd / "twin.fmu").stat().st_size > 0


def test_one_hour_heat_exchanger_bench_pair_track_and_gen_trackingbox(installed: Path, outside: dict) -> None:
    cwd: Path = outside["cwd"]  # type: ignore[assignment]
    tb = str(installed / "trackingbox")
    _ok(_run([tb, "bench", "heat-exchanger", "--out", "case", "--hours", "1", "--seed", "0"], **outside))
    spec = cwd / "case" / "spec.toml"
    source = Path(tomllib.loads(spec.read_text())["source"]["path"])
    assert installed.parent.resolve() in source.resolve().parents  # the bench used the installed library
    _ok(_run([tb, "pair", str(spec), "--method", "rga"], **outside))
    assert [p["parameter"] for p in tomllib.loads(spec.read_text())["pairs"]] == ["hx.kht"]

    _ok(_run([tb, "track", str(spec), "--report", "track"], **outside))
    result = json.loads((cwd / "track" / "result.json").read_text())
    truth = json.loads((cwd / "case" / "truth.json").read_text())["parameters"]["hx.kht"]
    assert result["complete"] is True
    # the plant's kht (910) from the spec's start (1000) in one hour: within 2 % of the truth
    assert abs(result["parameters"]["hx.kht"]["final"] - truth) <= 0.02 * truth
    assert (cwd / "track" / "summary.md").stat().st_size > 0  # the report package wrote the summary

    proc = _ok(_run([str(installed / "gen-trackingbox"), str(spec), "-o", "gen", "--compile"], **outside))
    generated = cwd / "gen" / "TwinTracking"
    assert sorted(p.name for p in generated.iterdir()) == [
        "TwinTracked.mo", "TwinTrackingBox.mo", "package.mo", "package.order"]
    assert "hx.kht tracks TI-102" in proc.stdout
    assert (cwd / "gen" / "TwinTracked.fmu").stat().st_size > 0
