"""The harnesses' worker limits: CPU seconds counted over the worker's whole process tree (a child in a
session of its own too), a worker that sleeps past its CPU limit left to finish, and a killed worker's
descendants gone with it."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from trackingbox.isolated import MARKER, run_worker, tree_cpu_seconds

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="needs Linux /proc")


def _state(pid: int) -> str | None:
    """The process's state letter, or None once it is gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_bytes().rsplit(b")", 1)[1].split()[0].decode()
    except (OSError, IndexError):
        return None


def test_a_worker_sleeping_past_its_cpu_limit_finishes(tmp_path):
    # 1.5 s asleep (no CPU) against a 0.5 CPU-s limit: the limit is not wall time, the result comes back
    code = f"import time, json; time.sleep(1.5); print('{MARKER}' + json.dumps({{'outcome': 'match'}}))"
    assert run_worker([sys.executable, "-c", code], timeout=600, cpu_limit=0.5) == {"outcome": "match"}


def test_a_grandchild_in_its_own_session_counts_and_is_killed(tmp_path):
    # the worker starts a child in a new session (as the compiler's front-end worker is) that spins
    # forever and writes its pid; the CPU limit must see the child's time and kill it with the worker
    pidfile = tmp_path / "child.pid"
    code = textwrap.dedent(f"""
        import subprocess, sys, time
        child = subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True)
        open({str(pidfile)!r}, "w").write(str(child.pid))
        child.wait()
    """)
    assert run_worker([sys.executable, "-c", code], timeout=600, cpu_limit=1.0) is None
    child = int(pidfile.read_text())
    deadline = time.monotonic() + 60  # a bound on the wait for the kernel to finish the kill, not a speed check
    while _state(child) not in (None, "Z", "X") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _state(child) in (None, "Z", "X")


def test_tree_cpu_seconds_agrees_with_the_processes_own_clocks(tmp_path):
    # a parent and a grandchild each burn CPU and report it from their own clock (time.process_time);
    # the parent reaps the first child (counted through the parent), the grandchild stays alive
    done = tmp_path / "ready.json"
    code = textwrap.dedent(f"""
        import json, subprocess, sys, time
        burn = "import time\\nt = time.process_time()\\nwhile time.process_time() - t < 0.6: pass\\nprint(time.process_time())"
        reaped = float(subprocess.run([sys.executable, "-c", burn], capture_output=True, text=True).stdout)
        live = subprocess.Popen([sys.executable, "-c", burn + "\\nimport sys; sys.stdout.flush(); sys.stdin.read()"],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, start_new_session=True)
        live_cpu = float(live.stdout.readline())
        t = time.process_time()
        while time.process_time() - t < 0.6: pass
        json.dump({{"reaped": reaped, "live": live_cpu, "own": time.process_time()}}, open({str(done)!r} + ".tmp", "w"))
        import os; os.replace({str(done)!r} + ".tmp", {str(done)!r})
        sys.stdin.read()
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE)
    try:
        while proc.poll() is None and not done.is_file():
            time.sleep(0.05)
        clocks = json.loads(done.read_text())
        measured = tree_cpu_seconds(proc.pid)
    finally:
        proc.stdin.close()
        proc.wait(timeout=60)
    expected = clocks["reaped"] + clocks["live"] + clocks["own"]
    # each interpreter's start-up and the live child's idle wait add a little; /proc counts in 1/100 s
    assert expected - 0.05 <= measured <= expected + 1.5
    assert measured > 1.7  # three burns of 0.6 s: the reaped child and the live grandchild are both counted
