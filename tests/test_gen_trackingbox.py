"""``gen-trackingbox``, the modellers' entry point, through its console script.

The script is the one ``pip`` wrote beside this environment's Python (``bin/gen-trackingbox``),
run as a user runs it: supervised (the default) and with ``TRACKINGBOX_SUPERVISE=0``, where it
raised ``TypeError`` (``_run(["generate", *None])``). Independent expectations: the spec's own
numbers (the pair's kp and Ti, the parameter's bounds and start, written by the fixture) in the
emitted box; ``trackingbox generate`` on the same spec, which the entry point must equal file
for file; and for a spec that does not exist one ``error:`` line naming it, exit 2, nothing written.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from _fixtures_generate import write_case

BIN = Path(sys.executable).parent
GEN = BIN / "gen-trackingbox"


def _run(argv: list[str], cwd: Path, supervise: bool) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "TRACKINGBOX_SUPERVISE": "1" if supervise else "0"}
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)


def _tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The ``Mini`` heater case (pair TI-102 -> hx.kht, kp 0.5, Ti 60 s, bounds [800, 1200]); its spec."""
    return write_case(tmp_path_factory.mktemp("gen-trackingbox") / "case")


def _by_generate(case: Path, out: Path) -> dict[str, bytes]:
    """What ``trackingbox generate SPEC -o OUT`` writes (the same command under its other name)."""
    proc = _run([str(BIN / "trackingbox"), "generate", str(case), "-o", str(out)], out.parent, True)
    assert proc.returncode == 0, proc.stderr
    return _tree(out)


@pytest.mark.parametrize("supervise", [True, False], ids=["supervised", "TRACKINGBOX_SUPERVISE=0"])
def test_gen_trackingbox_writes_the_box_of_the_spec(case: Path, supervise: bool, tmp_path: Path) -> None:
    proc = _run([str(GEN), str(case), "-o", str(tmp_path / "out")], tmp_path, supervise)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    written = _tree(tmp_path / "out")
    assert sorted(written) == ["TwinTracking/TwinTracked.mo", "TwinTracking/TwinTrackingBox.mo",
                               "TwinTracking/package.mo", "TwinTracking/package.order"]
    # beside each other, so that the spec's path the header gives relative to the output is the same
    assert written == _by_generate(case, tmp_path / "by-generate")
    box = written["TwinTracking/TwinTrackingBox.mo"].decode()

    def value(name: str) -> float:
        [found] = re.findall(rf"parameter Real {name}(?:\([^)]*\))? = ([-0-9.e+]+)", box)
        return float(found)

    # the spec's numbers, as the fixture wrote them
    assert (value("hx_kht_min"), value("hx_kht_max"), value("hx_kht_start")) == (800.0, 1200.0, 1000.0)
    assert (value("hx_kht_kp"), value("hx_kht_Ti")) == (0.5, 60.0)
    # the spec's gain is -0.005 K per W/(m2.K): a larger kht lowers TI-102, so the controller acts in reverse
    assert "reverseActing = true" in box
    assert "hx.kht tracks TI-102: kp = 0.5, Ti = 60 s, bounds [800, 1200]" in proc.stdout


@pytest.mark.parametrize("supervise", [True, False], ids=["supervised", "TRACKINGBOX_SUPERVISE=0"])
def test_gen_trackingbox_on_a_missing_spec_is_one_error_line(tmp_path: Path, supervise: bool) -> None:
    missing = tmp_path / "nope.toml"
    proc = _run([str(GEN), str(missing), "-o", str(tmp_path / "out")], tmp_path, supervise)
    assert proc.returncode == 2
    assert [line for line in proc.stderr.splitlines() if line.strip()] == [
        f"error: spec file {missing} does not exist"]
    assert not (tmp_path / "out").exists()


def test_gen_trackingbox_help_is_generates(tmp_path: Path) -> None:
    proc = _run([str(GEN), "--help"], tmp_path, False)
    assert proc.returncode == 0
    assert "usage: trackingbox generate" in proc.stdout and "--compile" in proc.stdout
