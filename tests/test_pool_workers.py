"""Pool workers end with the process they work for.

The process pool's workers are the forkserver's children, not those of the
process that submits to them: before ``exit_with_parent`` a ``trackingbox pair``
stopped with SIGTERM left its workers running their current simulations to the
end (26 CPU minutes each, seen on the evaporator train). A thread polling the
parent then failed under load (load 8-13 on two cores: the diagnose workers still
ran 10 s after their parent died); the workers now ask the kernel for SIGKILL when
their parent ends (Linux ``PR_SET_PDEATHSIG``). That alone still left the process
pool's workers running 60 s after their parent died, once they were really inside
their tasks: each held a copy of its fork server's lifeline pipe, so the server (the
parent their signal watches) never ended; they now close it. Independent expectation: the
operating system's process table (``os.kill(pid, 0)`` and ``/proc/PID/stat``) after
the submitting process was killed, while each worker still had a 60 s task to run
and this test kept every core busy; and the kernel's own answer
(``PR_GET_PDEATHSIG``) inside each worker.
"""
from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from trackingbox.analysis.executor import _alive

#: seconds a worker's task would still run when its parent is killed (the test waits far less)
TASK_SECONDS = 60.0
#: seconds the test waits at most for the workers to be gone: a bound on a hang, not a timing
#: (the kernel kills them when the parent ends; a loaded machine may be slow to reap them)
GONE_WITHIN = 60.0
LINUX = sys.platform.startswith("linux")

_CHILD = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    from trackingbox.analysis.executor import make_executor
    from trackingbox.diagnose.parallel import pool as worker_pool

    def busy(seconds):
        Path(f"started-{os.getpid()}").touch()  # the task runs: the worker is initialised
        t = time.monotonic()
        while time.monotonic() - t < seconds:
            pass
        return os.getpid()

    def probe(seconds):
        import threading
        from trackingbox.analysis.executor import parent_death_signal
        time.sleep(seconds)  # long enough for the other worker to take the other probe
        return [os.getpid(), parent_death_signal(), sorted(t.name for t in threading.enumerate())]

    if __name__ == "__main__":
        seconds = float(sys.argv[2])
        if sys.argv[1].startswith("probe-"):
            import json
            if sys.argv[1] == "probe-executor":
                with make_executor(workers=2) as ex:
                    found = [f.result() for f in [ex.submit(probe, seconds) for _ in range(2)]]
            else:
                with worker_pool(2) as pool:
                    found = [r.get() for r in [pool.apply_async(probe, (seconds,)) for _ in range(2)]]
            print(json.dumps(found), flush=True)
            sys.exit(0)
        kind, phase = sys.argv[1].split("-")
        if kind == "executor":
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
        if phase == "running":  # both workers initialised and in their task (a spawned one imports for seconds)
            while {p.name for p in Path().glob("started-*")} != {f"started-{p}" for p in pids}:
                time.sleep(0.05)
        print(" ".join(map(str, pids)), flush=True)
        time.sleep(2 * seconds)
""")


def _pool_child(tmp_path: Path, kind: str, phase: str = "running") -> tuple[subprocess.Popen[str], list[int]]:
    """A process with a pool of two workers, each given a 60 s task; its workers' pids once *phase*:
    ``running`` (both in their task) or ``starting`` (just made: a spawned worker still imports)."""
    script = tmp_path / "child.py"
    script.write_text(_CHILD)
    proc = subprocess.Popen([sys.executable, str(script), f"{kind}-{phase}", str(TASK_SECONDS)],
                            stdout=subprocess.PIPE, text=True, cwd=tmp_path)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    pids = [int(p) for p in line.split()]
    assert len(pids) == 2, line
    return proc, pids


@contextlib.contextmanager
def busy_machine():
    """A busy-loop process on every core while the block runs: the load the polling thread lost to."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    loops = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(cores)]
    try:
        yield len(loops)
    finally:
        for loop in loops:
            loop.kill()
        for loop in loops:
            loop.wait()


@pytest.mark.parametrize("kind", ["executor", "diagnose"])
@pytest.mark.parametrize("sig, phase", [(signal.SIGTERM, "running"), (signal.SIGKILL, "running"),
                                        (signal.SIGKILL, "starting")])
def test_workers_end_when_their_parent_is_killed(tmp_path: Path, kind: str, sig: signal.Signals,
                                                 phase: str) -> None:
    # "running": the workers are in their tasks, the kernel kills them as their parent ends;
    # "starting": the parent dies while its workers still start, so they set the signal after it
    # ended and must see that their parent changed and leave
    proc, pids = _pool_child(tmp_path, kind, phase)
    try:
        assert all(_alive(p) for p in pids)
        if phase == "running":
            assert {p.name for p in tmp_path.glob("started-*")} == {f"started-{p}" for p in pids}
        # every core busy from before the parent dies until its workers are gone (or the wait ends)
        with busy_machine() as loops:
            proc.send_signal(sig)
            proc.wait(timeout=GONE_WITHIN)
            assert proc.returncode == -sig
            died = time.monotonic()
            while any(_alive(p) for p in pids) and time.monotonic() - died < GONE_WITHIN:
                time.sleep(0.1)
            left = [p for p in pids if _alive(p)]
            assert not left, (f"workers {left} still run {time.monotonic() - died:.1f} s after their parent died "
                              f"of {sig.name} ({loops} busy loops beside them)")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for p in pids:
            if _alive(p):
                os.kill(p, signal.SIGKILL)


@pytest.mark.skipif(not LINUX, reason="PR_SET_PDEATHSIG is Linux's; elsewhere the workers poll their parent")
@pytest.mark.parametrize("kind", ["executor", "diagnose"])
def test_workers_hold_the_kernels_parent_death_signal_and_no_polling_thread(tmp_path: Path, kind: str) -> None:
    script = tmp_path / "child.py"
    script.write_text(_CHILD)
    proc = subprocess.run([sys.executable, str(script), f"probe-{kind}", "1.0"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    found = json.loads(proc.stdout)
    assert len({pid for pid, _, _ in found}) == 2, found  # both workers answered
    for _, sig, threads in found:
        assert sig == signal.SIGKILL
        assert "trackingbox-parent-watch" not in threads


def _exit_with_parent_in_child(parent: str, *, prctl: bool) -> subprocess.CompletedProcess[str]:
    """A process that calls ``exit_with_parent(PARENT)`` (with ``prctl`` hidden unless *prctl*), then waits 60 s."""
    code = textwrap.dedent(f"""
        import os, sys, time
        from trackingbox.analysis import executor
        if not {prctl!r}:
            executor._prctl = lambda: None  # a platform without prctl
        executor.exit_with_parent({parent})
        print("kept", flush=True)
        time.sleep(60)
    """)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)


@pytest.mark.skipif(not LINUX, reason="PR_SET_PDEATHSIG is Linux's")
def test_a_worker_whose_parent_already_ended_leaves_at_once() -> None:
    # the parent named is not this process's parent (nor its grandparent): it ended before prctl
    # was set, so no signal would come and the worker must leave by itself
    proc = _exit_with_parent_in_child("os.getppid() + 10**6", prctl=True)
    assert (proc.returncode, proc.stdout) == (1, "")


def test_without_prctl_a_thread_ends_the_worker_when_its_parent_is_gone() -> None:
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()  # reaped: no process has this pid now (or a new one, in which case the test says so)
    if _alive(gone.pid):
        pytest.skip(f"pid {gone.pid} was reused at once; the ended parent cannot be named")
    proc = _exit_with_parent_in_child(str(gone.pid), prctl=False)
    # the thread saw the parent gone and left through os._exit(1); a process it failed to end
    # would have slept its 60 s and exited 0
    assert proc.returncode == 1


def test_a_worker_whose_parent_runs_is_kept() -> None:
    # the parent of the child process is this test's process: exit_with_parent keeps the worker
    code = textwrap.dedent("""
        import os
        from trackingbox.analysis.executor import exit_with_parent, parent_death_signal
        exit_with_parent(os.getppid())
        print(parent_death_signal(), flush=True)
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == (str(int(signal.SIGKILL)) if LINUX else "None")


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
