"""``kill -9`` at random moments, then ``--resume``: the outputs of an uninterrupted run, bit for bit.

``trackingbox track`` and ``trackingbox estimate`` run as subprocesses on the
first-order heat-exchanger cases of ``_fixtures_tracking`` and
``_fixtures_estimation`` (CasADi FMUs, no Modelica compile). Each is killed
with SIGKILL several times at seeded random moments after it has started
writing, resumed with ``--resume`` each time, and the final files are compared
with those of an uninterrupted run: ``tracking.csv`` byte for byte and
``result.json`` with the wall-clock fields dropped (track); the ``--json``
document and the report's ``result.json`` with the wall-clock fields dropped
(estimate). A truncated, corrupt or foreign checkpoint is refused with one
``error:`` line and exit code 2.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from _fixtures_estimation import plant_data, write_case
from _fixtures_tracking import make_case

pytestmark = pytest.mark.slow  # about a minute on an idle machine: each case runs 5 subprocesses

KILLS = 3


def _cli(*args: str | Path) -> list[str]:
    return [sys.executable, "-m", "trackingbox.cli", *map(str, args)]


def _run(args: list[str], timeout: float = 300.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(args, capture_output=True, text=True, timeout=timeout)


def _run_and_kill(args: list[str], marker: Path, delay: float, timeout: float = 300.0) -> bool:
    """Start *args*; once *marker* exists wait *delay* s and SIGKILL. True if it was killed (not finished)."""
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.monotonic()
    try:
        while not marker.exists() and proc.poll() is None:
            if time.monotonic() - t0 > timeout:
                raise AssertionError(f"{marker} never appeared")
            time.sleep(0.01)
        time.sleep(delay)
        if proc.poll() is not None:
            return False
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        return proc.returncode == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _timed(args: list[str], marker: Path) -> tuple[subprocess.CompletedProcess[str], float]:
    """Run to the end; return the result and the seconds from *marker*'s appearance to the exit."""
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen = None
    while proc.poll() is None:
        if seen is None and marker.exists():
            seen = time.monotonic()
        time.sleep(0.01)
    end = time.monotonic()
    out, err = proc.communicate()
    result = subprocess.CompletedProcess(args, proc.returncode, out, err)
    assert result.returncode == 0, err
    return result, end - (seen if seen is not None else end)


def _verbose(args: list[str]) -> list[str]:
    """*args* with ``-v`` before the subcommand (INFO log lines on stderr)."""
    return [*args[:3], "-v", *args[3:]]


def _without(doc: dict, *keys: str) -> dict:
    return {k: v for k, v in doc.items() if k not in keys}


def _killed_resumes(args: list[str], marker: Path, busy: float, seed: int) -> int:
    """Kill *args* KILLS times at random moments within its busy time, resuming each time; count real kills."""
    rng = random.Random(seed)
    killed = 0
    for i in range(KILLS):
        # random moments inside what is left of the work: each resumed run has less to do
        delay = rng.uniform(0.05, 0.8) * busy * (1.0 - i / (KILLS + 1))
        killed += _run_and_kill(args if i == 0 else [*args, "--resume"], marker, delay)
    return killed


@pytest.fixture(scope="module")
def track_case(first_order_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_case(first_order_fmu, tmp_path_factory.mktemp("kill-track"))


@pytest.mark.parametrize("seed", [11])
def test_track_killed_and_resumed_writes_the_uninterrupted_bytes(track_case: Path, tmp_path: Path,
                                                                 seed: int) -> None:
    base = [*_cli("track", track_case, "--checkpoint-every", "25", "--json"), "--out"]
    full, busy = _timed([*base, str(tmp_path / "full")], tmp_path / "full" / "tracking.csv")
    out = tmp_path / "killed"
    killed = _killed_resumes([*base, str(out)], out / "tracking.csv", busy, seed)
    assert killed >= 1, "no kill landed inside the run: the test did not test anything"
    last = _run([*_verbose(base), str(out), "--resume"])
    assert last.returncode == 0, last.stderr
    assert "resumed at row" in last.stderr and "resumed at row 0 " not in last.stderr  # not a fresh start
    assert (out / "tracking.csv").read_bytes() == (tmp_path / "full" / "tracking.csv").read_bytes()
    ours = json.loads((out / "result.json").read_text())
    theirs = json.loads((tmp_path / "full" / "result.json").read_text())
    assert _without(ours, "seconds", "csv") == _without(theirs, "seconds", "csv")
    assert _without(json.loads(last.stdout), "seconds") == _without(json.loads(full.stdout), "seconds")


@pytest.mark.parametrize("damage", ["truncated", "corrupt", "csv-edited", "not-json"])
def test_track_refuses_a_damaged_checkpoint(track_case: Path, tmp_path: Path, damage: str) -> None:
    out = tmp_path / "run"
    args = [*_cli("track", track_case, "--checkpoint-every", "50", "--out", out)]
    from trackingbox.spec import load_spec
    from trackingbox.tracking.runtime import track

    assert not track(load_spec(track_case), out_dir=out, max_steps=120, checkpoint_every=50).complete
    ck, csv = out / "checkpoint.json", out / "tracking.csv"
    text = ck.read_text()
    if damage == "truncated":
        ck.write_text(text[: len(text) // 2])
    elif damage == "corrupt":  # still valid JSON: a digit of a saved state changed
        doc = json.loads(text)
        doc["controllers"]["controllers"]["k"]["u"] = 0.123456
        ck.write_text(json.dumps(doc))
    elif damage == "csv-edited":
        data = bytearray(csv.read_bytes())
        data[200] = ord("9") if data[200] != ord("9") else ord("8")
        csv.write_bytes(bytes(data))
    else:
        ck.write_bytes(b"\xff\xfe not json")
    before = csv.read_bytes()
    r = _run([*args, "--resume"])
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines[-1].startswith("error: ") and "Traceback" not in r.stderr
    assert "checkpoint" in lines[-1] and str(out) in lines[-1]
    assert csv.read_bytes() == before  # nothing half-done to the output


@pytest.fixture(scope="module")
def estimate_case(hx_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    table = plant_data(hx_fmu, 850.0, hours=1.0, noise=0.1, seed=3)
    return write_case(tmp_path_factory.mktemp("kill-estimate"), hx_fmu, table,
                      training=(0.0, 1800.0), validation=(1800.0, 3600.0))


@pytest.mark.parametrize("seed", [5])
def test_estimate_killed_and_resumed_gives_the_uninterrupted_result(estimate_case: Path, tmp_path: Path,
                                                                    seed: int) -> None:
    base = [*_cli("estimate", estimate_case, "--seed", "2", "--maxiter", "3", "--popsize", "5",
                  "--warmup", "600", "--refine-iterations", "2", "--json"), "--report"]
    full, busy = _timed([*base, str(tmp_path / "full")], tmp_path / "full" / "checkpoint.journal")
    out = tmp_path / "killed"
    killed = _killed_resumes([*base, str(out)], out / "checkpoint.journal", busy, seed)
    assert killed >= 1, "no kill landed inside the run: the test did not test anything"
    last = _run([*_verbose(base), str(out), "--resume"])
    assert last.returncode == 0, last.stderr
    # not a fresh start: evaluations recorded before the kills were served, not simulated again
    assert "served from the journal" in last.stderr and " 0 evaluations served" not in last.stderr
    assert _without(json.loads(last.stdout), "seconds") == _without(json.loads(full.stdout), "seconds")
    ours = json.loads((out / "result.json").read_text())
    theirs = json.loads((tmp_path / "full" / "result.json").read_text())
    assert _without(ours, "seconds") == _without(theirs, "seconds")


def test_estimate_refuses_a_damaged_or_foreign_journal(estimate_case: Path, tmp_path: Path) -> None:
    report = tmp_path / "report"
    args = _cli("estimate", estimate_case, "--maxiter", "1", "--popsize", "5", "--no-refine",
                "--warmup", "600", "--report", report)
    assert _run(args).returncode == 0
    journal = report / "checkpoint.journal"
    lines = journal.read_text().splitlines(keepends=True)
    assert len(lines) >= 3
    # an evaluation altered on disk: a value served from it would change the search
    seal, body = lines[1].split(" ", 1)
    journal.write_text("".join([lines[0], seal + " " + body.replace("1", "2", 1), *lines[2:]]))
    r = _run([*args, "--resume"])
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].startswith("error: journal ")
    assert "corrupt at line 2" in r.stderr
    # cut inside a line
    journal.write_text("".join(lines)[:-7])
    r = _run([*args, "--resume"])
    assert r.returncode == 2 and "truncated" in r.stderr
    # another run's journal (other seed)
    journal.write_text("".join(lines))
    r = _run([*args, "--seed", "9", "--resume"])
    assert r.returncode == 2 and "another run" in r.stderr and "seed" in r.stderr
