"""A bench case's measurements served over OPC UA as a simulated DCS (``trackingbox replay``).

Every tag of the case's spec (inputs, outputs, state tags) is a Double
variable ``ns=2;s=<tag>`` under the object ``Plant``. Row ``i`` of the
measurements (time ``t_i`` s from the first row) is written at wall-clock
``origin + t_i / speed`` with source timestamp ``origin + t_i`` (plant time:
the tracker sees the case's own sample spacing at any speed). A missing value
is written with a bad status. A historian's long export is served as the
historian has it: each tag at its own timestamps only, its bad-quality records
(empty values) with a bad status. Each variable is historized: a client that lost
its connection reads the rows it missed back (OPC UA HistoryRead). A server
restarted with the same *origin* writes the rows that fell due while it was
down into its history first, as a DCS's historian would have them, then goes
on live: a restart loses no row.
"""
from __future__ import annotations

import asyncio
import bisect
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np

from ..data.table import read_table
from ..errors import SpecError
from ..spec.parse import load_spec
from .opcua import PLANT_NAMESPACE, at, check_endpoint, make_server, utc

# asyncua is imported in the functions that use it (the offline commands do not pay for it: see .opcua)

log = logging.getLogger(__name__)

# deferred (start-up): asyncua is imported in the functions that talk OPC UA; it adds 0.37 s to an
# import of the package (python -X importtime, loaded 2-core machine) and only the online mode needs it

__all__ = ["ReplaySettings", "ReplayResult", "serve", "replay", "case_spec"]


@dataclass(frozen=True)
class ReplaySettings:
    """How to serve a case.

    Attributes
    ----------
    speed : float
        Plant seconds per wall-clock second (1: real time).
    origin : datetime or float, optional
        Wall-clock time of the case's first row (default: now), or seconds
        after the server is ready to serve. Give the same (absolute) origin,
        which the server logs, to a restarted server so it continues where
        the first one was.
    users : dict, optional
        ``user -> password``; when given, anonymous sessions are refused.
    certificate, private_key : Path, optional
        The server's certificate and key: Basic256Sha256 (sign and encrypt,
        or sign) endpoints only.
    stop_after : float, optional
        Stop after this many plant seconds (default: the end of the case).
    linger : float
        Wall-clock seconds to keep serving (history, last values) after the
        last row (``inf``: until stopped).
    """

    speed: float = 1.0
    origin: datetime | float | None = None
    users: dict[str, str] | None = None
    certificate: Path | None = None
    private_key: Path | None = None
    stop_after: float | None = None
    linger: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise SpecError(f"--speed must be a finite number > 0, got {self.speed!r}")
        if self.stop_after is not None and not (math.isfinite(self.stop_after) and self.stop_after >= 0):
            raise SpecError(f"--stop-after must be a finite number >= 0, got {self.stop_after!r}")


@dataclass(frozen=True)
class ReplayResult:
    """What a replay served."""

    url: str
    tags: tuple[str, ...]
    rows: int
    history_rows: int
    origin: datetime
    seconds: float

    def to_json(self) -> dict[str, Any]:
        return {"url": self.url, "tags": list(self.tags), "rows": self.rows, "history_rows": self.history_rows,
                "origin": self.origin.isoformat(), "seconds": self.seconds}


def _indexed_history() -> Any:
    """asyncua's in-memory history store, read by bisection on the source timestamps.

    Its own store scans every value of a node at every read: a client reading a long loss back a
    stretch at a time then costs the server O(history) per stretch (the 30-day soak: minutes per
    simulated day). The values come in time order (the replay writes them so), so the stretch's
    first and last are found by bisection. No period or count limit is used (none is set).
    """
    from asyncua.server.history import HistoryDict

    class IndexedHistory(HistoryDict):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self._stamps: dict[Any, list[Any]] = {}

        async def new_historized_node(self, node_id: Any, period: Any, count: int = 0) -> None:
            await super().new_historized_node(node_id, period, count)
            self._stamps[node_id] = []

        async def save_node_value(self, node_id: Any, datavalue: Any) -> None:
            self._datachanges[node_id].append(datavalue)
            self._stamps[node_id].append(datavalue.SourceTimestamp)

        async def read_node_history(self, node_id: Any, start: Any, end: Any, nb_values: int) -> Any:
            from asyncua import ua

            epoch = ua.get_win_epoch()
            if node_id not in self._stamps or start is None or start == epoch or (
                    end is not None and end != epoch and start > end):
                return await super().read_node_history(node_id, start, end, nb_values)
            stamps, data = self._stamps[node_id], self._datachanges[node_id]
            i = bisect.bisect_left(stamps, start)
            j = len(stamps) if end is None or end == epoch else bisect.bisect_right(stamps, end)
            results = data[i:j]
            if nb_values and len(results) > nb_values:
                results = results[:nb_values]
            cont = None
            if len(results) > self.max_history_data_response_size:
                cont = results[self.max_history_data_response_size].SourceTimestamp
                results = results[: self.max_history_data_response_size]
            return results, cont

    return IndexedHistory()


def _records(table: Any, tags: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(time, tag index, value)`` of every record to serve, in time order (tags in spec order within a time).

    A wide file gives every tag at every row (an empty cell: bad quality); a historian's long
    export gives each tag's own records only, its bad-quality records (empty values) included,
    as the historian would have sent them.
    """
    t_file = table["time"].to_numpy(dtype=float)
    t = t_file - t_file[0]
    breaks = table.attrs.get("breaks")
    parts_t, parts_k, parts_v = [], [], []
    for k, tag in enumerate(tags):
        v = table[tag].to_numpy(dtype=float)
        if breaks is None:  # wide: every row
            tk, vk = t, v
        else:
            ok = np.isfinite(v)
            bad_t = np.asarray(breaks.get(tag, ()), dtype=float) - t_file[0]
            tk, vk = np.r_[t[ok], bad_t], np.r_[v[ok], np.full(bad_t.size, np.nan)]
        parts_t.append(tk)
        parts_v.append(vk)
        parts_k.append(np.full(tk.size, k))
    times, tag_of, values = np.concatenate(parts_t), np.concatenate(parts_k), np.concatenate(parts_v)
    order = np.lexsort((tag_of, times))
    return times[order], tag_of[order], values[order]


def case_spec(case: str | Path) -> Path:
    """The spec of a case: *case* itself (a ``.toml``) or ``CASE/spec.toml``."""
    p = Path(case)
    spec = p / "spec.toml" if p.is_dir() else p
    if not spec.is_file():
        raise SpecError(f"case {case}: no spec.toml there (give a bench case directory or its spec.toml)")
    return spec


async def serve(case: str | Path, url: str, settings: ReplaySettings = ReplaySettings(), *,
                ready: Callable[[ReplayResult], None] | None = None,
                stop: asyncio.Event | None = None) -> ReplayResult:
    """Serve *case* at *url* until its last row (or *stop*); see the module docstring.

    Parameters
    ----------
    case : path
        A bench case directory (``spec.toml``, ``measurements.csv``) or a spec.
    url : str
        ``opc.tcp://HOST:PORT``.
    settings : ReplaySettings
    ready : callable, optional
        Called once the server listens (with the rows served so far).
    stop : asyncio.Event, optional
        Set it to stop early.
    """
    from asyncua import ua

    check_endpoint(url)
    spec = load_spec(case_spec(case))
    tags = list(spec.tags)
    table = read_table(spec.measurements, required=tags, allow_nan=True)
    times, tag_of, values = _records(table, tags)
    end = float(times[-1]) if settings.stop_after is None else min(float(times[-1]), settings.stop_after)
    n_records = int(np.searchsorted(times, end, side="right"))
    # records of one time are written together (a row of a wide file): [starts[i], starts[i + 1])
    starts = np.flatnonzero(np.r_[True, np.diff(times[:n_records]) > 0])
    starts = np.r_[starts, n_records]
    n_rows = int(starts.size - 1)
    server = await make_server(url, name="trackingbox replay", users=settings.users,
                               certificate=settings.certificate, private_key=settings.private_key)
    idx = await server.register_namespace(PLANT_NAMESPACE)
    plant = await server.nodes.objects.add_object(idx, "Plant")
    nodes = []
    # the server's historian keeps every scan, also of an unchanged value (asyncua's own historizing
    # stores changes only), so the store is written directly beside each write
    server.iserver.history_manager.set_storage(_indexed_history())
    history_store = server.iserver.history_manager.storage
    for tag in tags:
        var = await plant.add_variable(ua.NodeId(tag, idx), ua.QualifiedName(tag, idx),
                                       ua.Variant(math.nan, ua.VariantType.Double))
        await history_store.new_historized_node(var.nodeid, None, 0)
        nodes.append(var.nodeid)
    if idx != 2:
        log.warning("the plant namespace has index %d, not 2: node ids are ns=%d;s=<tag>", idx, idx)
    good, bad = ua.StatusCode(ua.StatusCodes.Good), ua.StatusCode(ua.StatusCodes.Bad)

    async def write(i: int) -> None:
        """Write row i: its records, each with its tag's value or a bad status."""
        stamp = at(origin, float(times[starts[i]]))
        for j in range(int(starts[i]), int(starts[i + 1])):
            v = float(values[j])
            ok = math.isfinite(v)
            dv = ua.DataValue(ua.Variant(v if ok else 0.0, ua.VariantType.Double), StatusCode=good if ok else bad,
                              SourceTimestamp=stamp, ServerTimestamp=datetime.now(timezone.utc))
            node = nodes[int(tag_of[j])]
            await server.write_attribute_value(node, dv)
            await history_store.save_node_value(node, dv)

    t_start = time.perf_counter()
    served = history = 0

    def due(i: int) -> float:
        """Wall-clock (epoch s) at which row i falls due."""
        return origin.timestamp() + float(times[starts[i]]) / settings.speed

    if not isinstance(settings.origin, (int, float)):
        origin = utc(settings.origin) if settings.origin is not None else datetime.now(timezone.utc)
        # rows that fell due before this server started (a restart): into the history first, before
        # it takes a client (a DCS restarted has its history; its clients see no old values as news)
        while served < n_rows and due(served) <= time.time():
            await write(served)
            served += 1
        history = served
        if history:
            log.info("wrote %d rows that fell due before the start into the history", history)
    async with server:
        if isinstance(settings.origin, (int, float)):
            origin = datetime.now(timezone.utc) + timedelta(seconds=float(settings.origin))
        if ready is not None:
            ready(ReplayResult(url, tuple(tags), served, history, origin, 0.0))
        log.info("serving %d tags of %s at %s from row %d of %d (speed %g, origin %s)", len(tags), spec.path,
                 url, served, n_rows, settings.speed, origin.isoformat())
        while served < n_rows and not (stop is not None and stop.is_set()):
            wait = due(served) - time.time()
            if wait > 0:
                if stop is not None:
                    try:
                        await asyncio.wait_for(stop.wait(), timeout=wait)
                        break
                    except asyncio.TimeoutError:
                        pass
                else:
                    await asyncio.sleep(wait)
            await write(served)
            served += 1
        if settings.linger > 0 and not (stop is not None and stop.is_set()):
            log.info("all %d rows served; serving on for %g s", served, settings.linger)
            if stop is not None:
                try:
                    await asyncio.wait_for(stop.wait(), timeout=None if math.isinf(settings.linger)
                                           else settings.linger)
                except asyncio.TimeoutError:
                    pass
            else:
                await asyncio.sleep(1e9 if math.isinf(settings.linger) else settings.linger)
    return ReplayResult(url, tuple(tags), served, history, origin, time.perf_counter() - t_start)


def replay(case: str | Path, url: str, settings: ReplaySettings = ReplaySettings()) -> ReplayResult:
    """Blocking :func:`serve` (``trackingbox replay``)."""
    return asyncio.run(serve(case, url, settings))
