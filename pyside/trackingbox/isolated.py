"""One model per worker process, as the compliance and MSL harnesses run them.

A worker is started in a session of its own, writes its result as one JSON object after
:data:`MARKER` on stdout (:func:`write_result`), and is read back by :func:`run_worker`; at a
time-out, or when the harness is interrupted (:func:`stop_workers`), its whole process group
and every process below it are killed, so a model that hangs or crashes its compiler never
takes the harness with it. The time-out is in wall seconds and, where asked, in CPU seconds of
the worker's processes together (:func:`tree_cpu_seconds`), which a loaded machine does not move.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from typing import Any

#: The line a worker's result follows on its stdout.
MARKER = "@@RESULT@@"

#: Worker processes running now (killed on interruption).
LIVE: set[subprocess.Popen] = set()


def write_result(result: dict[str, Any]) -> None:
    """In a worker: its result, after :data:`MARKER`, as the last thing on stdout."""
    sys.stdout.write("\n" + MARKER + json.dumps(result, default=str) + "\n")
    sys.stdout.flush()


def stop_workers() -> None:
    """Kill every running worker's process group and descendants."""
    for proc in list(LIVE):
        kill_tree(proc.pid)


def interrupt(signum: int, frame: object) -> None:
    """A SIGTERM handler: end the harness as Ctrl-C does (its ``finally`` stops the workers)."""
    raise KeyboardInterrupt


def _proc_table() -> dict[int, tuple[int, int]]:
    """pid -> (parent pid, clock ticks of CPU: own user + system and waited-for children's), from ``/proc``."""
    table: dict[int, tuple[int, int]] = {}
    try:
        entries = [e for e in os.listdir("/proc") if e.isdigit()]
    except OSError:
        return table
    for entry in entries:
        try:
            with open(f"/proc/{entry}/stat", "rb") as fh:
                fields = fh.read().rsplit(b")", 1)[1].split()
            # after "pid (comm)": state ppid pgrp session ...; utime stime cutime cstime at 11-14
            table[int(entry)] = (int(fields[1]), sum(int(f) for f in fields[11:15]))
        except (OSError, IndexError, ValueError):
            continue
    return table


def _descendants(root: int, table: dict[int, tuple[int, int]]) -> list[int]:
    """*root* and every live process below it."""
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in table.items():
        children.setdefault(ppid, []).append(pid)
    found, todo = [], [root]
    while todo:
        pid = todo.pop()
        found.append(pid)
        todo.extend(children.get(pid, ()))
    return found


def kill_tree(root: int) -> None:
    """SIGKILL *root*'s process group and every live descendant (a worker in a session of its own too)."""
    for pid in _descendants(root, _proc_table()):
        try:
            os.kill(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
    try:
        os.killpg(root, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def tree_cpu_seconds(root: int) -> float:
    """CPU seconds (user + system) of process *root* and its live descendants, their reaped children included.

    Read from ``/proc``: each live process's own time and the time of the children it has waited for, so
    a compiler's finished ``cc1`` counts through the process that ran it, and a front-end worker started
    in a session of its own counts through its parent. 0.0 where ``/proc`` is absent.
    """
    table = _proc_table()
    total = sum(table[pid][1] for pid in _descendants(root, table) if pid in table)
    return total / os.sysconf("SC_CLK_TCK")


def run_worker(cmd: list[str], timeout: float, cpu_limit: float | None = None) -> dict[str, Any] | None:
    """Run the worker *cmd*; its result, or None when it gave none in time (killed).

    In time: within *timeout* s of wall time and, where *cpu_limit* is given, before the worker's
    processes together (it and its descendants: the C compiler and the front end's worker too) have
    used *cpu_limit* CPU seconds; a CPU limit does not move with the machine's load, a wall limit does.
    A worker that ended without a result gives ``{"outcome": "crashed", "message": ...}`` naming
    the signal that killed it or its exit code, with the end of its stderr.
    """
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, errors="replace")
    LIVE.add(proc)
    end = time.monotonic() + timeout
    try:
        while True:
            try:
                out, err = proc.communicate(timeout=max(0.0, min(2.0, end - time.monotonic())))
                break
            except subprocess.TimeoutExpired:
                over = cpu_limit is not None and tree_cpu_seconds(proc.pid) > cpu_limit
                if not over and time.monotonic() < end:
                    continue
                kill_tree(proc.pid)
                proc.communicate()
                return None
    finally:
        LIVE.discard(proc)
    at = out.rfind(MARKER)
    if at >= 0:
        return json.loads(out[at + len(MARKER):].strip())
    if proc.returncode < 0:
        return {"outcome": "crashed",
                "message": f"worker killed by signal {signal.Signals(-proc.returncode).name}: {err.strip()[-500:]}"}
    return {"outcome": "crashed", "message": f"worker exited with {proc.returncode}: {err.strip()[-1500:]}"}
