"""Executors for the parallel stages: the machine's cores, or a Dask cluster.

Step tests, Sobol samples, estimation's population and its finite-difference
Jacobian columns are independent simulations. They are submitted to a
:class:`concurrent.futures.Executor` from :func:`make_executor`: the calling
process (``workers=1``), a local process pool (the default), a local Dask
cluster (``address="local"``) or an existing Dask cluster (``address=
"tcp://host:8786"``). Each worker process extracts and instantiates an FMU once
(:func:`trackingbox.simulation.models.cached_model`, keyed by the FMU's path and content) and reuses it for
every task it receives; the tasks do the same arithmetic wherever they run, so
the results do not depend on the executor.
"""
from __future__ import annotations

import ctypes
import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from typing import Any

from ..errors import AnalysisError

try:
    from multiprocessing import forkserver as _forkserver
except ImportError:  # pragma: no cover - a platform without fork servers (Windows)
    _forkserver = None  # type: ignore[assignment]

logger = logging.getLogger(__name__)

#: seconds to wait for a Dask scheduler to answer (``--scheduler tcp://...``)
CONNECT_TIMEOUT = 10.0
#: seconds to wait for the first worker of a Dask cluster (a scheduler without workers would hang)
WORKER_TIMEOUT = 60.0
#: ``--scheduler`` value that starts a local Dask cluster of ``--workers`` processes on 127.0.0.1
LOCAL = "local"
#: seconds between a pool worker's checks that the process it works for still runs, where the
#: platform has no parent-death signal (:func:`exit_with_parent`)
PARENT_POLL = 0.5
#: Linux ``prctl`` options: the signal this process gets when its parent ends, set and read
PR_SET_PDEATHSIG, PR_GET_PDEATHSIG = 1, 2


class SerialExecutor(Executor):
    """Run each task at once in the calling process (``workers=1``).

    No process start-up cost and exceptions keep their traceback; FMUs are
    cached in this process.
    """

    def __init__(self) -> None:
        self._shutdown = False

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        if self._shutdown:
            raise RuntimeError("cannot submit after shutdown")
        fut: Future[Any] = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - handed to the future like a pool would
            fut.set_exception(exc)
        return fut

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._shutdown = True


class DaskExecutor(Executor):
    """Tasks on a Dask cluster: ``Client.get_executor(pure=False)``, closing what it started on shutdown.

    Parameters
    ----------
    client : distributed.Client
        Connected client.
    cluster : distributed.LocalCluster, optional
        A cluster this executor started (closed on shutdown); ``None`` for an existing one.
    """

    def __init__(self, client: Any, cluster: Any = None) -> None:
        self.client = client
        self.cluster = cluster
        # pure=False: every submission is a task of its own (no key shared between equal calls)
        self._inner = client.get_executor(pure=False)

    @property
    def workers(self) -> int:
        """Workers connected to the scheduler now."""
        return len(self.client.scheduler_info(n_workers=-1).get("workers", {}))

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        return self._inner.submit(fn, *args, **kwargs)

    def map(self, fn: Callable[..., Any], *iterables: Any, timeout: float | None = None,
            chunksize: int = 1) -> Iterator[Any]:
        return self._inner.map(fn, *iterables, timeout=timeout)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        try:
            self._inner.shutdown(wait=wait)
        finally:
            try:
                self.client.close()
            finally:
                if self.cluster is not None:
                    self.cluster.close()


_DaskExecutor = DaskExecutor  # the former private name


def stop_executor(executor: Executor, *, wait: bool = True) -> None:
    """Shut *executor* down; with ``wait=False`` cancel what has not started and stop what runs.

    A local process pool's workers are terminated (an interrupted estimation
    must not wait for, nor leave behind, a run in progress); a Dask cluster's
    running tasks are cancelled through their futures.
    """
    if wait:
        executor.shutdown(wait=True)
        return
    processes = list((getattr(executor, "_processes", None) or {}).values())
    executor.shutdown(wait=False, cancel_futures=True)
    for process in processes:  # ProcessPoolExecutor: no public way to stop a running task before 3.14
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=5)


def default_workers() -> int:
    """Cores this process may use (``os.sched_getaffinity`` where available)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def make_executor(address: str | None = None, workers: int | None = None, *,
                  timeout: float | None = None, start_method: str | None = None) -> Executor:
    """An executor for independent simulation tasks: one way for every parallel stage.

    Parameters
    ----------
    address : str, optional
        ``None``: local worker processes (a process pool; the default path).
        ``"local"`` (:data:`LOCAL`): a Dask ``LocalCluster`` of *workers* processes
        (one thread each) on 127.0.0.1, started here and closed on shutdown.
        Otherwise the address of an existing Dask distributed scheduler
        (``tcp://host:8786``): tasks run on its workers, which must see the FMU
        under the same path (a shared file system) and have trackingbox installed.
    workers : int, optional
        Number of local worker processes (process pool or local cluster); default:
        all cores this process may use. ``1`` without *address* runs tasks in the
        calling process (:class:`SerialExecutor`). Ignored for an existing cluster
        (its workers are what it has).
    timeout : float, optional
        Seconds to wait for the scheduler to answer (default :data:`CONNECT_TIMEOUT`)
        and, on an existing cluster, for its first worker (default :data:`WORKER_TIMEOUT`).
    start_method : {"forkserver", "spawn"}, optional
        How the process pool starts its workers (default: forkserver where there is
        one). ``"spawn"`` makes them children of this process, so that their CPU time
        counts as this process's children's once the pool is shut down.

    Returns
    -------
    concurrent.futures.Executor
        Use as a context manager, or call ``shutdown()``. On every executor each
        worker process extracts and instantiates an FMU once (:func:`trackingbox.simulation.models.cached_model`).

    Raises
    ------
    AnalysisError
        If *workers* is not positive, the scheduler cannot be reached, or the
        cluster has no worker.

    Examples
    --------
    >>> with make_executor(workers=1) as ex:
    ...     ex.submit(pow, 2, 10).result()
    1024
    """
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise AnalysisError(f"--workers must be an integer >= 1, got {workers!r}")
    if address == LOCAL:
        return _local_cluster(workers or default_workers())
    if address:
        return _connect(address, timeout)
    if workers is None:
        workers = default_workers()
    if workers == 1:
        return SerialExecutor()
    logger.info("running on %d local worker processes", workers)
    # fresh worker processes: an FMU instance (and its extracted files) must not be shared
    # with the parent through fork
    method = start_method or ("forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn")
    if method not in ("forkserver", "spawn"):
        raise AnalysisError(f"start_method must be 'forkserver' or 'spawn' (fresh processes), not {method!r}")
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method),
                               initializer=exit_with_parent, initargs=(os.getpid(),))


def _alive(pid: int) -> bool:
    """Whether process *pid* still runs (a zombie, dead but not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            state = fh.read().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True  # no /proc (macOS): the signal test is all there is
    return state not in ("Z", "X")


def _parent_of(pid: int) -> int | None:
    """The parent process of *pid* (``/proc/PID/stat``), or None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            return int(fh.read().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return None


def _prctl() -> Any:
    """libc's ``prctl`` (Linux), or None on a platform without it."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


def parent_death_signal() -> int | None:
    """The signal the kernel sends this process when its parent ends (0: none), None without ``prctl``."""
    prctl = _prctl()
    if prctl is None:
        return None
    value = ctypes.c_int(0)
    if prctl(PR_GET_PDEATHSIG, ctypes.byref(value), 0, 0, 0) != 0:
        return None
    return value.value


def _release_fork_server() -> bool:
    """Close this fork-server child's copy of its fork server's lifeline; False if it cannot be found.

    The fork server leaves when the write end of its "alive" pipe is closed everywhere. Its
    owner holds one copy, and every child it forks is handed another (so that the child
    could use the same server): as long as a worker lives, its server lives, and as long as
    the server lives, the worker's parent-death signal never comes. Closing the worker's copy
    leaves the server's life to its owner alone (and to any fork-server child that keeps its
    copy: in trackingbox the process pool of :func:`make_executor` is the only user of the fork
    server, and all its workers close theirs). The pipe is found through CPython's
    ``multiprocessing.forkserver`` internals; where they change, the worker polls instead.
    """
    server = getattr(_forkserver, "_forkserver", None)
    fd = getattr(server, "_forkserver_alive_fd", None)  # set by the server's child code (CPython 3.8+)
    if fd is None:
        return False
    try:
        os.close(fd)
    except OSError:
        return False
    server._forkserver_alive_fd = None  # a process this worker starts gets a fork server of its own
    return True


def exit_with_parent(parent: int) -> None:
    """Pool worker initializer: end this worker as soon as process *parent* is gone.

    A pool's workers must not outlive the process they work for when it dies without
    shutting its pool down (SIGTERM, SIGKILL, a crash): each would run its current
    simulation to the end (tens of CPU minutes on the evaporator train) for nobody.

    On Linux the kernel does it: ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` has the worker
    killed the moment its parent process ends, however busy the machine (a thread
    polling the parent, as before, was not scheduled in time at load 8-13 on two
    cores). The parent is *parent* itself for spawned workers (the diagnose pool,
    estimation's pool); the kernel sends the signal when the *thread* that started the
    worker ends, so such a pool must be used within the thread that made it (each of
    ours is). The default process pool's workers are children of the fork server
    *parent* started, a single-threaded process that leaves when its pipe from *parent*
    reaches end of file: each worker first closes its own copy of that pipe
    (:func:`_release_fork_server`; before, the workers kept their server alive and the
    server kept them alive, 60 s after *parent* died of SIGKILL), so *parent*'s end
    ends the server and the server's end kills its workers. Right after setting the
    signal, the worker checks that *parent* still runs (its parent, or its parent's
    parent for the fork server's children); if it ended before (the worker's parent
    is then another process, ``init`` or a sub-reaper) the worker leaves at once: no
    signal would come.

    Where there is no ``prctl`` (macOS, Windows), or a fork-server child cannot find
    its server's pipe, a daemon thread checks every :data:`PARENT_POLL` seconds that
    *parent* still runs and leaves through ``os._exit``.
    """
    prctl = _prctl()
    if prctl is not None and prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
        direct = os.getppid()
        if direct == parent:
            return  # a spawned worker: the kernel signals it when parent ends
        if _parent_of(direct) != parent:
            os._exit(1)  # the parent ended before the signal was set: nobody waits for this worker
        if _release_fork_server():
            return  # the fork server ends with parent, and the kernel signals this worker then

    def watch() -> None:
        while _alive(parent):
            time.sleep(PARENT_POLL)
        os._exit(1)

    threading.Thread(target=watch, name="trackingbox-parent-watch", daemon=True).start()


def _quiet_dask() -> None:
    """Dask's own INFO lines (scheduler, nanny, comms) only when trackingbox logs at DEBUG (``-vv``)."""
    if not logger.isEnabledFor(logging.DEBUG):
        logging.getLogger("distributed").setLevel(logging.WARNING)


def _local_cluster(workers: int) -> DaskExecutor:
    """A Dask ``LocalCluster`` of *workers* one-thread processes on 127.0.0.1 (HTTP on a free local port)."""
    # deferred (start-up): dask.distributed adds 0.2-0.43 s to an import of the package (python -X
    # importtime); only a --scheduler run uses it
    from dask.distributed import Client, LocalCluster

    _quiet_dask()
    try:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0")
    except Exception as exc:  # noqa: BLE001 - start-up failures come as OSError/TimeoutError/RuntimeError
        raise AnalysisError(f"--scheduler local: cannot start a Dask cluster of {workers} workers on "
                            f"127.0.0.1: {exc}") from None
    try:
        client = Client(cluster)
    except BaseException:
        cluster.close()
        raise
    logger.info("running on a local Dask cluster of %d workers (%s)", workers, cluster.scheduler_address)
    return DaskExecutor(client, cluster)


def _connect(address: str, timeout: float | None) -> DaskExecutor:
    """A client of the existing Dask scheduler at *address*, with at least one worker."""
    # deferred (start-up): dask.distributed adds 0.2-0.43 s to an import of the package (python -X
    # importtime); only a --scheduler run uses it
    from dask.distributed import Client

    _quiet_dask()
    wait = CONNECT_TIMEOUT if timeout is None else float(timeout)
    try:
        client = Client(address, timeout=wait)
    except Exception as exc:  # noqa: BLE001 - dask raises OSError/TimeoutError/ValueError variants
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise AnalysisError(f"--scheduler {address}: cannot connect to a Dask scheduler there within "
                            f"{wait:g} s ({reason})") from None
    try:
        client.wait_for_workers(1, timeout=WORKER_TIMEOUT if timeout is None else float(timeout))
    except Exception:  # noqa: BLE001 - a TimeoutError
        client.close()
        raise AnalysisError(f"--scheduler {address}: the scheduler has no worker (waited "
                            f"{WORKER_TIMEOUT if timeout is None else timeout:g} s)") from None
    executor = DaskExecutor(client)
    logger.info("running on the Dask scheduler %s (%d workers)", address, executor.workers)
    return executor
