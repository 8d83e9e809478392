"""The simulation service's model cache: one open FMU per process, path, content, tolerance and thread.

Every stage that simulates the twin many times takes its :class:`~trackingbox.fmu.FMUModel`
from :func:`cached_model` (a worker process of a pool or a Dask cluster keeps its FMUs across
tasks); a run that needs an instance of its own (the tracking loop's two twins, the tracked
FMU in validation, a bench's plant) opens one with :func:`open_model`. Nothing else constructs
an :class:`~trackingbox.fmu.FMUModel`.
"""
from __future__ import annotations

import hashlib
import logging
import os
import socket
import threading
from collections import Counter, OrderedDict
from pathlib import Path
from typing import Any

from ..errors import AnalysisError
from ..fmu import FMUModel
from ..fmu.info import Interface

logger = logging.getLogger(__name__)

#: most FMUs one thread keeps open; its least recently used one is closed past it (a long-lived
#: Dask worker sees the FMUs of many runs)
MAX_CACHED_MODELS = 8

_MODELS: OrderedDict[tuple[str, str, float, int], Any] = OrderedDict()
_DIGESTS: dict[str, tuple[tuple[int, int, int], str]] = {}
_OPENS: Counter[str] = Counter()
_LOCK = threading.Lock()


def fmu_digest(path: str | os.PathLike[str]) -> str:
    """SHA-256 of the file at *path*, computed again only when its size, mtime or inode change.

    Parameters
    ----------
    path : path-like
        FMU file.

    Returns
    -------
    str
        Hex digest.

    Raises
    ------
    AnalysisError
        If the file cannot be read here (on a cluster: the FMU must be on a file
        system every worker sees under the same path).
    """
    name = str(Path(path).resolve())
    try:
        st = os.stat(name)
        stamp = (st.st_size, st.st_mtime_ns, st.st_ino)
        known = _DIGESTS.get(name)
        if known is not None and known[0] == stamp:
            return known[1]
        h = hashlib.sha256()
        with open(name, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError as exc:
        raise AnalysisError(f"FMU {name} cannot be read on host {socket.gethostname()} (process {os.getpid()}): "
                            f"{exc.strerror or exc}; on a cluster every worker must see the FMU under the "
                            "same path") from None
    _DIGESTS[name] = (stamp, h.hexdigest())
    return h.hexdigest()


def cached_model(path: str | os.PathLike[str], tolerance: float = 1e-6) -> Any:
    """The :class:`trackingbox.fmu.FMUModel` for *path*, extracted and instantiated once per process.

    The cache is keyed by the FMU's resolved path, its content (SHA-256,
    :func:`fmu_digest`), *tolerance* and the calling thread: a worker process
    that lives longer than one run (a Dask worker) opens a rewritten FMU afresh
    and never runs a stale one, and two threads of one worker (a Dask worker
    with ``--nthreads 2``) never share an instance, which is not thread-safe.
    At most :data:`MAX_CACHED_MODELS` per thread stay open (least recently used closed).

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
    name = str(Path(path).resolve())
    with _LOCK:
        key = (name, fmu_digest(name), float(tolerance), threading.get_ident())
        model = _MODELS.get(key)
        if model is None or model.closed:
            logger.debug("process %d opens %s", os.getpid(), name)
            model = FMUModel(name, tolerance=key[2])
            _OPENS[name] += 1
            _MODELS[key] = model
        _MODELS.move_to_end(key)
        mine = [k for k in _MODELS if k[3] == key[3]]  # another thread's model may be running
        for old in mine[:max(0, len(mine) - MAX_CACHED_MODELS)]:
            _MODELS.pop(old).close()
        return model


def model_opens() -> dict[str, int]:
    """How many times this process has opened each FMU (path -> count) through :func:`cached_model`.

    On a cluster, ``client.run(model_opens)`` gives every worker's counts: one
    per FMU and worker, however many tasks each ran.
    """
    with _LOCK:
        return dict(_OPENS)


def clear_model_cache() -> None:
    """Close and forget every cached FMU of this process (the open counts stay)."""
    with _LOCK:
        models = list(_MODELS.values())
        _MODELS.clear()
    for model in models:
        try:
            model.close()
        except Exception:  # noqa: BLE001 - closing is best effort
            logger.debug("closing %s failed", model, exc_info=True)


def open_model(path: str | os.PathLike[str], *, tolerance: float = 1e-6, interface: Interface | None = None
               ) -> FMUModel:
    """A new :class:`~trackingbox.fmu.FMUModel` of its own (not cached): the caller closes it."""
    return FMUModel(path, tolerance=tolerance, interface=interface)


def forget_models() -> None:
    """A fresh worker process owns no FMU yet: drop the entries a fork inherited (without closing them)."""
    with _LOCK:
        _MODELS.clear()


def close_models() -> None:
    """Close the twins this process has opened through :func:`cached_model` (best effort)."""
    try:
        clear_model_cache()
    except Exception:  # noqa: BLE001 - closing is best effort
        logger.debug("closing the cached twins failed", exc_info=True)
