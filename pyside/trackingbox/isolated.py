"""One model per worker process, as the compliance and MSL harnesses run them.

A worker is started in a session of its own, writes its result as one JSON object after
:data:`MARKER` on stdout (:func:`write_result`), and is read back by :func:`run_worker`; at a
time-out, or when the harness is interrupted (:func:`stop_workers`), its whole process group
is killed, so a model that hangs or crashes its compiler never takes the harness with it.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
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
    """Kill every running worker's process group."""
    for proc in list(LIVE):
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def interrupt(signum: int, frame: object) -> None:
    """A SIGTERM handler: end the harness as Ctrl-C does (its ``finally`` stops the workers)."""
    raise KeyboardInterrupt


def run_worker(cmd: list[str], timeout: float) -> dict[str, Any] | None:
    """Run the worker *cmd*; its result, or None when it gave none within *timeout* s (killed).

    A worker that ended without a result gives ``{"outcome": "crashed", "message": ...}`` naming
    the signal that killed it or its exit code, with the end of its stderr.
    """
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, errors="replace")
    LIVE.add(proc)
    try:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
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
