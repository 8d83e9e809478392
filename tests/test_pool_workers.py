"""Pool workers end with the process they work for.

The process pool's workers are the forkserver's children, not those of the
process that submits to them: before ``exit_with_parent`` a ``trackingbox pair``
stopped with SIGTERM left its workers running their current simulations to the
end (26 CPU minutes each, seen on the evaporator train). Independent
expectation: the operating system's process table (``os.kill(pid, 0)`` and
``/proc/PID/stat``) a few seconds after the submitting process was killed, while
each worker still had a 60 s task to run.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from trackingbox.analysis.executor import PARENT_POLL, _alive

#: seconds a worker's task would still run when its parent is killed (the test waits far less)
TASK_SECONDS = 60.0

_CHILD = textwrap.dedent("""
    import os, sys, time
    from trackingbox.analysis.executor import make_executor
    from trackingbox.diagnose.parallel import pool as worker_pool

    def busy(seconds):
        t = time.monotonic()
        while time.monotonic() - t < seconds:
            pass
        return os.getpid()

    if __name__ == "__main__":
        seconds = float(sys.argv[2])
        if sys.argv[1] == "executor":
            ex = make_executor(workers=2)
            futures = [ex.submit(busy, seconds) for _ in range(2)]
            while len(ex._processes) < 2:
                time.sleep(0.05)
            pids = list(ex._processes)
        else:
            cm = worker_pool(2)
            pool = cm.__enter__()
            results = [pool.apply_async(busy, (seconds,)) for _ in range(2)]
            pids = [p.pid for p in pool._pool]
        time.sleep(1.0)  # the tasks are running
        print(" ".join(map(str, pids)), flush=True)
        time.sleep(2 * seconds)
""")


def _pool_child(tmp_path: Path, kind: str) -> tuple[subprocess.Popen[str], list[int]]:
    script = tmp_path / "child.py"
    script.write_text(_CHILD)
    proc = subprocess.Popen([sys.executable, str(script), kind, str(TASK_SECONDS)], stdout=subprocess.PIPE,
                            text=True, cwd=tmp_path)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    pids = [int(p) for p in line.split()]
    assert len(pids) == 2, line
    return proc, pids


@pytest.mark.parametrize("kind", ["executor", "diagnose"])
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_workers_end_when_their_parent_is_killed(tmp_path: Path, kind: str, sig: signal.Signals) -> None:
    proc, pids = _pool_child(tmp_path, kind)
    try:
        assert all(_alive(p) for p in pids)  # busy with their 60 s tasks
        proc.send_signal(sig)
        proc.wait(timeout=30)
        assert proc.returncode == -sig
        died = time.monotonic()
        while any(_alive(p) for p in pids) and time.monotonic() - died < 10 * PARENT_POLL + 5.0:
            time.sleep(0.1)
        left = [p for p in pids if _alive(p)]
        assert not left, f"workers {left} still run {time.monotonic() - died:.1f} s after their parent died of {sig.name}"
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for p in pids:
            if _alive(p):
                os.kill(p, signal.SIGKILL)


def test_alive_tells_a_running_process_from_a_reaped_and_a_zombie_one() -> None:
    assert _alive(os.getpid())
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    # exited but not reaped: a zombie still answers os.kill(pid, 0)
    while _zombie_state(proc.pid) != "Z" and time.monotonic() < deadline:
        time.sleep(0.05)
    if _zombie_state(proc.pid) == "Z":
        assert not _alive(proc.pid)
    else:
        pytest.skip("no /proc/PID/stat on this system: the zombie case cannot be observed")
    proc.wait()
    assert not _alive(proc.pid)


def _zombie_state(pid: int) -> str | None:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return None
