"""Executors for the analysis runs: the machine's cores, or a Dask cluster.

Step tests and Sobol samples are independent simulations. They are submitted
to a :class:`concurrent.futures.Executor`; each worker process opens an FMU once
(:func:`cached_model`) and reuses it for every task it receives.
"""
from __future__ import annotations

import logging
import multiprocessing
import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from pathlib import Path
from typing import Any

from ..errors import AnalysisError

logger = logging.getLogger(__name__)

_MODELS: dict[tuple[str, float], Any] = {}
_LOCK = threading.Lock()


def cached_model(path: str | os.PathLike[str], tolerance: float = 1e-6) -> Any:
    """The :class:`trackingbox.fmu.FMUModel` for *path*, opened once per process.

    Parameters
    ----------
    path : path-like
        FMU file.
    tolerance : float
        Solver tolerance (part of the cache key).

    Returns
    -------
    trackingbox.fmu.FMUModel
    """
    from ..fmu import FMUModel

    key = (str(Path(path).resolve()), float(tolerance))
    with _LOCK:
        model = _MODELS.get(key)
        if model is None or model.closed:
            logger.debug("process %d opens %s", os.getpid(), key[0])
            model = FMUModel(key[0], tolerance=key[1])
            _MODELS[key] = model
        return model


def clear_model_cache() -> None:
    """Close and forget every cached FMU of this process."""
    with _LOCK:
        for model in _MODELS.values():
            model.close()
        _MODELS.clear()


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


class _DaskExecutor(Executor):
    """A Dask ``Client.get_executor()`` that closes its client on shutdown."""

    def __init__(self, client: Any) -> None:
        self._client = client
        self._inner = client.get_executor()

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        return self._inner.submit(fn, *args, **kwargs)

    def map(self, fn: Callable[..., Any], *iterables: Any, timeout: float | None = None,
            chunksize: int = 1) -> Iterator[Any]:
        return self._inner.map(fn, *iterables, timeout=timeout)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        try:
            self._inner.shutdown(wait=wait)
        finally:
            self._client.close()


def default_workers() -> int:
    """Cores this process may use (``os.sched_getaffinity`` where available)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def make_executor(address: str | None = None, workers: int | None = None) -> Executor:
    """An executor for independent simulation tasks.

    Parameters
    ----------
    address : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``). When
        given, tasks run on that cluster through ``Client(address).get_executor()``
        (needs ``dask[distributed]``; the FMU path must be readable by the workers).
    workers : int, optional
        Number of local worker processes; default: all cores this process may
        use. ``1`` runs tasks in the calling process (:class:`SerialExecutor`).

    Returns
    -------
    concurrent.futures.Executor
        Use as a context manager, or call ``shutdown()``.

    Raises
    ------
    AnalysisError
        If *workers* is not positive, dask is not installed, or the scheduler
        cannot be reached.

    Examples
    --------
    >>> with make_executor(workers=1) as ex:
    ...     ex.submit(pow, 2, 10).result()
    1024
    """
    if address:
        try:
            from dask.distributed import Client
        except ImportError:
            raise AnalysisError(f"--scheduler {address} needs Dask distributed, which is not installed: "
                                "pip install 'dask[distributed]' (or 'trackingbox[dask]')") from None
        try:
            client = Client(address, timeout=30)
        except Exception as exc:  # noqa: BLE001 - dask raises OSError/TimeoutError variants
            raise AnalysisError(f"cannot connect to the Dask scheduler at {address}: {exc}") from None
        logger.info("running on Dask scheduler %s", address)
        return _DaskExecutor(client)
    if workers is None:
        workers = default_workers()
    if workers < 1:
        raise AnalysisError(f"--workers must be at least 1, got {workers}")
    if workers == 1:
        return SerialExecutor()
    logger.info("running on %d local worker processes", workers)
    # fresh worker processes: an FMU instance (and its extracted files) must not be shared
    # with the parent through fork
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method))
