"""Property-based fuzzing of the command line (issue 13): option values and output locations.

Every refusal is exit 2 with exactly one ``error:`` line and nothing written;
the oracle for numeric options is the documented range, evaluated here with
Python's own float parsing.
"""
from __future__ import annotations

import contextlib
import io
import math
import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trackingbox.cli import main
from trackingbox.errors import OutputError
from trackingbox.io import check_output

FUZZ = settings(max_examples=50, deadline=10000, suppress_health_check=[HealthCheck.function_scoped_fixture])

NUMBER_TEXT = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-10**30, max_value=10**30).map(str),
    st.sampled_from(["nan", "inf", "-inf", "0", "-0", "1e-9", "1e400", "", "abc", "0x10", "1_000", " 5 "]),
    st.text(max_size=12),
)

#: command, the option, its range as (lower bound, inclusive?), whether it is an integer, other arguments
OPTIONS = [
    (["simulate", "x.fmu", "-o", "out/r.csv"], "--step", (0.0, False), False),
    (["simulate", "x.fmu", "-o", "out/r.csv"], "--tolerance", (1e-12, True), False),
    (["estimate", "spec.toml"], "--warmup", (0.0, True), False),
    (["estimate", "spec.toml"], "--global-grid", (0.0, False), False),
    (["estimate", "spec.toml"], "--workers", (1, True), True),
    (["estimate", "spec.toml"], "--popsize", (1, True), True),
    (["track", "spec.toml", "--out", "out/track"], "--checkpoint-every", (1, True), True),
    (["pair", "spec.toml", "--report", "out/pair"], "--interval", (0.0, False), False),  # at most 1e9 s
    (["validate", "spec.toml", "--fmu", "x.fmu"], "--band", (0.0, False), False),
]


def _in_range(text: str, low: tuple[float, bool], integer: bool, high: float | None) -> bool:
    try:
        value = int(text, 10) if integer else float(text)
    except ValueError:
        return False
    if not integer and not math.isfinite(value):
        return False
    bound, inclusive = low
    if not (value >= bound if inclusive else value > bound):
        return False
    return high is None or value <= high


def run(argv: list[str], cwd: Path) -> tuple[int, str]:
    err = io.StringIO()
    old = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            code = main(argv)
    finally:
        os.chdir(old)
    return code, err.getvalue()


@FUZZ
@given(case=st.sampled_from(OPTIONS), text=NUMBER_TEXT)
def test_a_numeric_option_is_range_checked_before_anything_runs(tmp_path: Path, case: tuple, text: str) -> None:
    argv, option, low, integer = case
    work = Path(tempfile.mkdtemp(dir=tmp_path))
    code, err = run([*argv, option, text], work)
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    # the inputs do not exist: a value in range is refused for the missing file, one out of range for itself
    assert code == 2 and len(errors) == 1, err
    high = {"--tolerance": 0.5, "--workers": 256, "--interval": 1e9}.get(option)
    if _in_range(text.strip() if not integer else text, low, integer, high):
        assert f"argument {option}" not in errors[0]
    else:
        assert f"argument {option}" in errors[0]
        assert len(errors[0]) < 400
    assert list(work.iterdir()) == []  # nothing written


@FUZZ
@given(text=st.one_of(st.text(max_size=40), st.sampled_from(["", ".", "~nosuchuser/x", "a\x00b", "x" * 300,
                                                           "/proc/x/y", "/dev/null"])),
       kind=st.sampled_from(["file", "dir"]))
def test_check_output_returns_a_path_or_one_output_error(tmp_path: Path, text: str, kind: str) -> None:
    old = os.getcwd()
    os.chdir(tmp_path)
    try:
        path = check_output(text, "-o", kind=kind)
    except OutputError as exc:
        assert str(exc).startswith("-o") and len(str(exc)) < 400
    else:
        assert isinstance(path, Path)
    finally:
        os.chdir(old)
    assert list(tmp_path.iterdir()) == []  # checking writes nothing


def test_an_output_equal_to_an_input_is_refused_and_the_input_kept(tmp_path: Path) -> None:
    fmu = tmp_path / "twin.fmu"
    fmu.write_bytes(b"an FMU")
    code, err = run(["simulate", str(fmu), "--stop", "1", "-o", str(fmu)], tmp_path)
    assert code == 2 and "it is an input" in err and fmu.read_bytes() == b"an FMU"


@pytest.mark.parametrize(("target", "message"), [
    ("afile/out.csv", "is a file, not a directory"),
    ("existing", "is an existing directory"),
    ("", "-o .: is an existing directory"),  # argparse makes Path("") the current directory
    ("~nosuchuser/x.csv", "no user 'nosuchuser'"),
])
def test_bad_output_locations_are_refused_with_the_reason(tmp_path: Path, target: str, message: str) -> None:
    (tmp_path / "afile").write_text("x")
    (tmp_path / "existing").mkdir()
    code, err = run(["simulate", "x.fmu", "--stop", "1", "-o", target], tmp_path)
    assert code == 2 and message in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "existing"]
