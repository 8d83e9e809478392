"""Worker processes for the diagnosis: independent twin runs and screening jobs over the machine's cores.

Diagnosis makes many runs that do not depend on each other: the null model's
series and its output Jacobian (``1 + p`` runs per window), the re-linearised
sensor screens, and the screening jobs of the expensive entries (a fouling
ramp's search, a ``compile``-only entry's patch compiled and linearised). With
:func:`pool` active they are spread over worker processes; without it they run
here, one after the other. Either way the same arithmetic is done on the same
numbers, so the results do not depend on the number of workers.

The workers are fresh processes (spawned: an FMU instance and its extracted
files must not be shared through a fork; and a spawned worker is this process's
child, so its CPU time is counted here, unlike a forkserver's). Each keeps the FMUs it has opened (:func:`trackingbox.simulation.models.cached_model`)
for the next task, and closes them when the pool ends. The pool is joined when
the ``with`` block ends, so the workers' CPU time counts as this process's
children's time there (:class:`trackingbox.diagnose.stage` reports it per phase).

As with ``estimate(..., workers=2)``, a script that calls :func:`trackingbox.diagnose.diagnose`
with more than one worker must guard its top level (``if __name__ == "__main__":``): a
spawned worker imports the caller's main module. ``DiagnoseSettings(workers=1)`` runs
everything in the calling process.
"""
from __future__ import annotations

import logging
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from multiprocessing.util import Finalize
from typing import Any

from ..data.view import keep_tables
from ..analysis.executor import exit_with_parent, make_executor, stop_executor
from ..simulation.models import close_models, forget_models

log = logging.getLogger(__name__)

_ACTIVE: list[Any] = []


def _init_worker(parent: int) -> None:
    """A fresh worker owns no FMU yet; it closes the ones it opens when it exits, and ends with *parent*."""
    forget_models()
    exit_with_parent(parent)
    # the diagnosis's measurement file, read once per worker (its jobs lay it on windows again and again)
    keep_tables()
    # run by the worker's own exit (a forkserver child leaves through os._exit, past atexit)
    Finalize(None, close_models, exitpriority=10)


def _call(task: tuple[Callable[..., Any], tuple[Any, ...]]) -> Any:
    fn, args = task
    return fn(*args)


class _ExecutorPool:
    """A :mod:`concurrent.futures` executor (a Dask cluster's) behind the two calls this module makes of a pool."""

    def __init__(self, executor: Any) -> None:
        self.executor = executor

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], chunksize: int = 1) -> Any:
        return self.executor.map(fn, items)

    def apply_async(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> Any:
        return _Handle(self.executor.submit(fn, *args))


class _Handle:
    def __init__(self, future: Any) -> None:
        self._future = future

    def get(self) -> Any:
        return self._future.result()


@contextmanager
def pool(workers: int, scheduler: str | None = None) -> Iterator[Any]:
    """Spread :func:`map_calls` over *workers* processes inside the ``with`` block (1: run here).

    With *scheduler* (a Dask scheduler's address, or ``"local"``:
    :func:`trackingbox.analysis.executor.make_executor`) the jobs go to that
    cluster's workers instead of spawned processes, whose CPU time is then not
    this process's children's. Nested use keeps the outer pool; a worker never
    starts a pool of its own.
    """
    if workers <= 1 or _ACTIVE or multiprocessing.parent_process() is not None:
        yield None
        return
    if scheduler:
        ex = make_executor(scheduler, workers)
        _ACTIVE.append(_ExecutorPool(ex))
        ok = False
        try:
            yield _ACTIVE[-1]
            ok = True
        finally:
            _ACTIVE.pop()
            stop_executor(ex, wait=ok)
        return
    p = multiprocessing.get_context("spawn").Pool(workers, initializer=_init_worker, initargs=(os.getpid(),))
    _ACTIVE.append(p)
    ok = False
    try:
        yield p
        ok = True
    finally:
        _ACTIVE.remove(p)
        if ok:
            p.close()
            p.join()
        else:
            p.terminate()
            p.join()


def active() -> bool:
    """True inside :func:`pool` with more than one worker."""
    return bool(_ACTIVE)


def map_calls(fn: Callable[..., Any], args: Sequence[tuple[Any, ...]]) -> list[Any]:
    """``[fn(*a) for a in args]``, over the active pool's workers when there is one (order kept).

    *fn* must be a module-level function and *args* picklable when a pool is active.
    """
    if not _ACTIVE or len(args) < 2:
        return [fn(*a) for a in args]
    return list(_ACTIVE[-1].map(_call, [(fn, tuple(a)) for a in args], chunksize=1))


def submit(fn: Callable[..., Any], args: tuple[Any, ...]) -> Callable[[], Any]:
    """Start ``fn(*args)`` on the active pool (or run it here now); returns a function giving its result."""
    if not _ACTIVE:
        try:
            value = fn(*args)
        except Exception as exc:  # noqa: BLE001 - raised where the result is asked for, as from a worker
            error = exc  # the except clause unbinds ``exc`` when it ends

            def failed() -> Any:
                raise error
            return failed
        return lambda: value
    handle = _ACTIVE[-1].apply_async(_call, ((fn, tuple(args)),))
    return handle.get
