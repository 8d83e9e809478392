"""The estimate, track, generate and validate commands through ``trackingbox.cli.main``.

One small case for the module: the ``Mini`` heater twin of ``_fixtures_generate``
(one state, ``kht`` trackable). The "plant" is the same twin with
``hx.kht = 900`` (the spec starts at 1000), its noise-free output the
measurements, so every stage has one independent expectation: the plant's 900.
Each command is checked for its exit code, the shape of its ``--json``
document (exactly one document on stdout) and, for bad input, one
``error: ...`` line on stderr naming the thing and where it is, with exit code 2.
"""
from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from _fixtures_generate import write_case

KHT_PLANT = 900.0

pytestmark = pytest.mark.compile


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """Exit code, stdout and stderr of ``trackingbox ARGV``."""
    from trackingbox.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("error: ")]


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The Mini case with measurements from the kht = 900 plant; returns the spec path."""
    from trackingbox.compiler import compile_model
    from trackingbox.fmu import FMUModel

    spec = write_case(tmp_path_factory.mktemp("cli-stages") / "case")
    root = spec.parent
    compile_model(root / "Mini", "Mini.Twin", backend="embedded", output=root / "twin.fmu")
    grid = np.arange(0.0, 7200.0 + 1e-9, 10.0)
    qin = np.where(grid < 2400.0, 50000.0, np.where(grid < 4800.0, 40000.0, 55000.0))
    with FMUModel(root / "twin.fmu") as plant:
        sim = plant.simulate(stop_time=7200.0, output_interval=10.0, parameters={"hx.kht": KHT_PLANT},
                             inputs=pd.DataFrame({"time": grid, "Qin": qin}), outputs=["ThOut"])
    pd.DataFrame({"time": grid, "QI-100": qin, "TI-102": sim["ThOut"].to_numpy()}).to_csv(
        root / "measurements.csv", index=False)
    return spec


@pytest.fixture(scope="module")
def generated(case: Path) -> dict[str, Any]:
    """``trackingbox generate SPEC -o DIR --compile --json``, run once for the module."""
    code, out, err = run_cli(["generate", str(case), "-o", str(case.parent / "generated"), "--compile", "--json"])
    return {"code": code, "out": out, "err": err}


# ---------------------------------------------------------------- estimate


def test_estimate_json_finds_plant_kht(case: Path, tmp_path: Path) -> None:
    report = tmp_path / "est"
    # the plant run starts from the twin's own initial state, so no warm-up: the twin at 900 is the plant
    code, out, _ = run_cli(["estimate", str(case), "--json", "--maxiter", "0", "--warmup", "0",
                            "--report", str(report)])
    assert code == 0
    doc = json.loads(out)
    assert set(doc) == {"parameters", "training", "validation", "evaluations", "seconds", "refinement",
                        "identifiability", "uncertainty"}
    # the embedded twin provides directional derivatives; "auto" takes them unless its runs are native
    from trackingbox.spec import load_spec

    assert doc["refinement"]["jacobian"] == ("fd" if _runs_native(load_spec(case).twin) else "exact")
    assert set(doc["validation"]) == {"nrmse", "nrmse_initial"}
    assert doc["parameters"]["hx.kht"] == pytest.approx(KHT_PLANT, rel=0.01)
    assert doc["training"]["nrmse"]["TI-102"] < 1e-3  # noise-free data of the same model
    assert (report / "parameters.md").is_file() and (report / "fit_TI-102.png").read_bytes()[:4] == b"\x89PNG"


def test_estimate_missing_spec_is_one_error_line(tmp_path: Path) -> None:
    code, out, err = run_cli(["estimate", str(tmp_path / "nope.toml"), "--json"])
    assert code == 2 and out == ""
    [line] = error_lines(err)
    assert "nope.toml" in line


def test_estimate_bad_toml_names_file_and_line(case: Path, tmp_path: Path) -> None:
    bad = tmp_path / "spec.toml"
    lines = case.read_text().splitlines()
    lines[2] = "sample_time = = 10"  # line 3
    bad.write_text("\n".join(lines) + "\n")
    code, out, err = run_cli(["estimate", str(bad)])
    assert code == 2 and out == ""
    [line] = error_lines(err)
    assert "spec.toml" in line and "line 3" in line


# ---------------------------------------------------------------- track


def test_track_json_reaches_plant_kht(case: Path, tmp_path: Path) -> None:
    code, out, err = run_cli(["track", str(case), "--json", "--out", str(tmp_path / "run"),
                              "--report", str(tmp_path / "rep")])
    assert code == 0
    doc = json.loads(out)
    assert set(doc) == {"variables", "parameters", "seconds"}
    assert set(doc["variables"]["TI-102"]) == {"nrmse_untracked", "nrmse_tracked"}
    assert doc["parameters"]["hx.kht"]["final"] == pytest.approx(KHT_PLANT, rel=0.01)
    assert doc["variables"]["TI-102"]["nrmse_tracked"] < 0.2 * doc["variables"]["TI-102"]["nrmse_untracked"]
    assert "tracking: row" in err
    assert (tmp_path / "run" / "tracking.csv").is_file()
    summary = (tmp_path / "rep" / "summary.md").read_text()
    assert "| TI-102 | `hx.kht` |" in summary and "![parameter hx.kht](parameter_hx.kht.png)" in summary


def test_track_bad_option_is_one_error_line(case: Path, tmp_path: Path) -> None:
    code, out, err = run_cli(["track", str(case), "--out", str(tmp_path / "run"), "--checkpoint-every", "0"])
    assert code == 2 and out == ""
    assert error_lines(err) == ["error: trackingbox track: argument --checkpoint-every: must be an integer >= 1, "
                                "got '0' (see trackingbox track --help)"]
    assert not (tmp_path / "run").exists()  # nothing half-written


def test_track_carry_zero_is_the_restart_path(case: Path, tmp_path: Path) -> None:
    # --carry 0 re-initialises the integrator at every parameter change, the default carries the
    # controller's small moves; both reach the plant's kht (the independent expectation)
    finals, integrator = {}, {}
    for label, extra in (("default", []), ("restart", ["--carry", "0"])):
        code, out, _ = run_cli(["track", str(case), "--json", "--out", str(tmp_path / label), *extra])
        assert code == 0
        finals[label] = json.loads(out)["parameters"]["hx.kht"]["final"]
        integrator[label] = json.loads((tmp_path / label / "result.json").read_text())["integrator"]
    assert integrator["restart"]["carried"] == 0 and integrator["restart"]["restarts"] > 100
    assert integrator["default"]["carried"] > 100
    for label in finals:
        assert finals[label] == pytest.approx(KHT_PLANT, rel=0.01), label


@pytest.mark.parametrize("extra, message", [
    (["--carry", "-0.1"], "error: trackingbox track: argument --carry: must be a finite number >= 0, got '-0.1' "
                          "(see trackingbox track --help)"),
    (["--carry", "0", "--controllers", "continuous"], "error: --carry applies to the discrete controllers"),
])
def test_track_bad_carry_is_one_error_line(case: Path, tmp_path: Path, extra: list[str], message: str) -> None:
    code, out, err = run_cli(["track", str(case), "--out", str(tmp_path / "run"), *extra])
    assert code == 2 and out == ""
    [line] = error_lines(err)
    assert line.startswith(message)
    assert not (tmp_path / "run").exists()  # nothing half-written


def test_track_without_pairs_names_the_spec(case: Path, tmp_path: Path) -> None:
    spec = write_case(tmp_path / "c", pairs=False)
    for name in ("twin.fmu", "measurements.csv"):
        (spec.parent / name).write_bytes((case.parent / name).read_bytes())
    code, _, err = run_cli(["track", str(spec), "--out", str(tmp_path / "run")])
    assert code == 2
    [line] = error_lines(err)
    assert str(spec) in line and "[[pairs]]" in line


# ---------------------------------------------------------------- generate


def test_generate_json_and_compile(generated: dict[str, Any], case: Path) -> None:
    assert generated["code"] == 0
    doc = json.loads(generated["out"])
    assert set(doc) == {"package", "package_dir", "files", "tracked_model", "box_model", "library",
                        "patched_source", "variants", "controllers", "compile"}
    assert doc["tracked_model"] == "TwinTracking.TwinTracked" and doc["patched_source"] is None
    assert doc["variants"] == []  # the twin's own library class takes the pattern: no library variant
    [c] = doc["controllers"]
    assert (c["tag"], c["parameter"], c["min"], c["max"], c["start"]) == ("TI-102", "hx.kht", 800.0, 1200.0, 1000.0)
    assert (c["kp"], c["ti"]) == (0.5, 60.0)  # the spec's kp and ti, taken as given
    assert Path(doc["compile"]["fmu"]).is_file() and doc["compile"]["backend"] == "embedded"
    assert sorted(Path(f).name for f in doc["files"]) == ["TwinTracked.mo", "TwinTrackingBox.mo", "package.mo",
                                                          "package.order"]


def test_generate_plain_library_refuses_with_the_lines_to_add(tmp_path: Path) -> None:
    spec = write_case(tmp_path / "c", library="Plain")
    code, out, err = run_cli(["generate", str(spec), "-o", str(tmp_path / "g"), "--json"])
    assert code == 2 and out == ""
    assert err.startswith("error: ") and "use_kht_in" in err
    assert not (tmp_path / "g" / "TwinTracking").exists()


# ---------------------------------------------------------------- validate


def test_validate_json_agrees_with_python(generated: dict[str, Any], case: Path, tmp_path: Path) -> None:
    fmu = json.loads(generated["out"])["compile"]["fmu"]
    code, out, _ = run_cli(["validate", str(case), "--fmu", fmu, "--json", "--report", str(tmp_path / "rep")])
    assert code == 0
    doc = json.loads(out)
    assert set(doc) == {"variables", "parameters", "agreement", "window", "seconds", "report"}
    assert set(doc["variables"]["TI-102"]) == {"nrmse_untracked", "nrmse_tracked", "nrmse_python",
                                               "converged_at", "band"}
    kht = doc["parameters"]["hx.kht"]
    assert kht["final"] == pytest.approx(KHT_PLANT, rel=0.01) and kht["within_bounds"] is True
    assert doc["agreement"] < 0.05 and doc["window"] == [3600.0, 7200.0]
    assert Path(doc["report"]).name == "validation.md"


@pytest.mark.parametrize(("extra", "expected"), [
    (["--fmu", "missing.fmu"], "missing.fmu does not exist"),
    (["--fmu", "x.fmu", "--band", "-1"], "argument --band: must be a finite number > 0, got '-1'"),
])
def test_validate_bad_input_is_one_error_line(case: Path, tmp_path: Path, extra: list[str], expected: str) -> None:
    extra = [str(tmp_path / a) if a.endswith(".fmu") else a for a in extra]
    code, out, err = run_cli(["validate", str(case), "--json", *extra])
    assert code == 2 and out == ""
    [line] = error_lines(err)
    assert expected in line


def _runs_native(fmu) -> bool:
    """Whether the twin's runs go through the native stepper (then ``jacobian="auto"`` takes fd)."""
    from trackingbox.estimation.objective import runs_native
    from trackingbox.simulation.models import cached_model as _model

    return runs_native(_model(fmu))
