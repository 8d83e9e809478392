"""Live tracking against an OPC UA server (``trackingbox track SPEC --live opc.tcp://HOST:PORT``).

The tracker subscribes to the spec's tags (node ids from ``[live]``, default
``ns=2;s=<tag>``) and records every sample it receives, with its source
timestamp, in ``OUT/live_measurements.csv`` (a historian's long form:
``tag,time,value``). The offline runtime does the tracking: the recorded
samples are read through the same :class:`~trackingbox.data.MeasurementView`
(gap rule, stoppages, the twin's inputs), and one
:class:`~trackingbox.tracking.runtime.TrackingLoop` is driven sample by
sample with :meth:`~trackingbox.tracking.runtime.TrackingLoop.extend` and
``run(max_steps=...)``. So ``OUT/tracking.csv``, ``checkpoint.json`` and
``result.json`` are those of ``trackingbox track``; time 0 is the first
sample's source timestamp (kept in ``OUT/live.json``).

Row ``k`` is run (the twins stepped to ``t_k+1``) once every tag has a sample
at or after ``t_k+1``, so the twin runs in real time, one sample behind the
plant. A tag with nothing for ``stale_after`` s of plant time (the newest
timestamp of any tag) does not hold the others up: its samples are missing
there and its controller holds (mode ``hold``), resuming bumplessly when it
is back. When the server goes away the tracker waits (no row is invented),
reconnects with exponential back-off, and reads the samples it missed back
with HistoryRead before going on live, so no row is lost.

With ``[live] publish = "opc.tcp://..."`` the tracker serves its results:
``ns=2;s=parameter:<name>``, ``tracked:<tag>``, ``untracked:<tag>``,
``mode:<tag>``, the band ``parameter_lo:<name>`` / ``parameter_hi:<name>`` and its
``lack_of_fit`` where some output is untracked (the CSV's columns), updated after every row with the row's plant time as
source timestamp.
"""
from __future__ import annotations

import asyncio
import csv
import io
import json
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np

from ..checkpoint import CheckpointFile
from ..data.series import heartbeat_max_gap
from ..data.view import MeasurementView
from ..errors import CheckpointError, DataError, LiveError, SpecError
from ..io import write_text_atomic
from ..spec.model import Spec
from ..spec.parse import check_against_fmu
from ..tracking.loop import TrackingLoop
from ..tracking.result import TrackingResult
from . import livestream
from .livestream import LiveMeasurements
from .opcua import CLIENT_URI, RESULTS_NAMESPACE, Credentials, at, check_endpoint, make_server, utc

# asyncua is imported in the functions that use it (the offline commands do not pay for it: see .opcua)

log = logging.getLogger(__name__)

# deferred (start-up): asyncua is imported in the functions that talk OPC UA; it adds 0.37 s to an
# import of the package (python -X importtime, loaded 2-core machine) and only the online mode needs it

__all__ = ["LiveSettings", "LiveResult", "track_live", "RECORD_NAME", "LIVE_NAME", "STATUS_NAME"]

#: The samples received, as a historian's long form.
RECORD_NAME = "live_measurements.csv"
#: The run's time origin and endpoint (for --resume).
LIVE_NAME = "live.json"
#: The tracker's state for the live view (rewritten, whole, about twice a second; see docs/online.md).
STATUS_NAME = "live_status.json"
#: Wall-clock seconds between two writes of the status file (a connection's change is written at once).
STATUS_EVERY = 0.5
#: Wall-clock seconds a tag behind the plant's clock must also have been silent to be stale.
STALE_GRACE = 5.0
#: Samples of plant time (per tag) read back from the server's history in one request after a loss.
BACKFILL_ROWS = 360
#: Samples the subscription may queue while the history is read back; past this many the queue is
#: emptied and what was in it is read from the history too (the back-fill reads up to its newest
#: sample): a tracker days behind a fast replay held every sample that came meanwhile (the 30-day
#: soak: ~380 bytes each, +35 MiB of peak RSS). 10,000 samples are a few MiB
QUEUE_LIMIT = 10_000
#: First client handle of the monitored items (one per tag; asyncua numbers its own from 201)
_HANDLE0 = 1_000_000


@dataclass(frozen=True)
class LiveSettings:
    """How to run live.

    Attributes
    ----------
    url : str
        The plant's OPC UA endpoint.
    credentials : Credentials, optional
        User name and password (required when the spec's ``[live] auth = "user"``).
    start : datetime, optional
        Track from this plant time on (samples before it are read from the
        server's history); default: from the first sample received.
    stop_after : float, optional
        Stop once the rows up to this many plant seconds from the start are done.
    idle_timeout : float, optional
        Stop when no new sample has come for this many wall-clock seconds
        (connected or not); default: run until stopped.
    backoff : tuple of float
        First and longest wait (s) between reconnection attempts.
    poll : float
        Wall-clock seconds between looks at the received samples.
    timeout : float
        Seconds a connection attempt or a request may take.
    windowed : bool
        Hold only the samples the loop can still reach and hand it windows of rows
        (:mod:`.livestream`: memory flat in the run's length); False: rebuild the whole view
        of the record at every batch (what a co-simulation twin always does).
    """

    url: str
    credentials: Credentials | None = None
    start: datetime | None = None
    stop_after: float | None = None
    idle_timeout: float | None = None
    backoff: tuple[float, float] = (0.5, 30.0)
    poll: float = 0.1
    timeout: float = 4.0
    windowed: bool = True

    def __post_init__(self) -> None:
        check_endpoint(self.url, "--live")
        for name in ("stop_after", "idle_timeout"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise SpecError(f"{name} must be a finite number > 0, got {v!r}")
        if not (0 < self.backoff[0] <= self.backoff[1]) or not (self.poll > 0 and self.timeout > 0):
            raise SpecError(f"back-off {self.backoff!r}, poll {self.poll!r} and timeout {self.timeout!r} "
                            "must be positive (and the first back-off not above the longest)")


@dataclass(frozen=True)
class LiveResult:
    """Outcome of :func:`track_live`."""

    tracking: TrackingResult
    origin: datetime
    samples: int
    backfilled: int
    connections: int
    stale_events: int

    def to_json(self) -> dict[str, Any]:
        return {**self.tracking.to_json(), "live": {
            "origin": self.origin.isoformat(), "rows": self.tracking.steps, "samples": self.samples,
            "backfilled": self.backfilled, "connections": self.connections, "stale_events": self.stale_events}}


# --------------------------------------------------------------------------- the record of samples

class _Record:
    """Samples received per tag, deduplicated by source timestamp, appended to the long-form CSV."""

    def __init__(self, path: Path, tags: list[str], *, resume: bool) -> None:
        self.path = path
        self.tags = tags
        self.last: dict[str, datetime | None] = {t: None for t in tags}
        #: per tag: the newest sample of good quality, and whether the newest sample was bad
        self.good: dict[str, datetime | None] = {t: None for t in tags}
        self.bad: dict[str, bool] = {t: False for t in tags}
        self.count = 0
        self.first: datetime | None = None
        if resume and path.exists():
            self._load()
        else:
            write_text_atomic(path, "tag,time,value\n")
        self._fd = os.open(path, os.O_WRONLY | os.O_APPEND)
        self._pending: list[str] = []

    def _load(self) -> None:
        with open(self.path, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            if next(reader, None) != ["tag", "time", "value"]:
                raise CheckpointError(f"{self.path} is not a live record (header tag,time,value); "
                                      "run without --resume to start over")
            for row in reader:
                if len(row) != 3 or row[0] not in self.last:
                    raise CheckpointError(f"{self.path} has a malformed row {row!r}; run without --resume")
                t = datetime.fromisoformat(row[1])
                self.last[row[0]] = t
                self.bad[row[0]] = not row[2]
                if row[2]:
                    self.good[row[0]] = t
                    self.count += 1
                self.first = t if self.first is None or t < self.first else self.first

    def add(self, tag: str, stamp: datetime, value: float | None) -> bool:
        """Record one sample (``None``: bad quality, an empty value); False if not newer than the last.

        A bad-quality sample is kept as a historian keeps it (an empty value): the view of the
        record then breaks the tag's interpolation there, as it does reading the historian's
        own export, and a tag reported by exception is not held across a loss of its link.
        """
        stamp = utc(stamp)
        last = self.last[tag]
        if last is not None and stamp <= last:
            return False
        self.last[tag] = stamp
        if self.first is None or stamp < self.first:
            self.first = stamp
        if value is None or not math.isfinite(value):
            self.bad[tag] = True
            self._pending.append(f"{tag},{stamp.isoformat()},\n")
            return True
        self.good[tag] = stamp
        self.bad[tag] = False
        self._pending.append(f"{tag},{stamp.isoformat()},{value!r}\n")
        self.count += 1
        return True

    def flush(self) -> None:
        if self._pending:
            os.write(self._fd, "".join(self._pending).encode("utf-8"))  # whole lines in one write
            self._pending.clear()

    def close(self) -> None:
        self.flush()
        os.close(self._fd)


# --------------------------------------------------------------------------- the subscription's queue

def _stamp(dv: Any) -> datetime | None:
    stamp = dv.SourceTimestamp or dv.ServerTimestamp
    return utc(stamp) if stamp is not None else None


class _Inbox:
    """The subscription's samples not taken yet, ``(tag, DataValue)`` in the order they came.

    While :attr:`spill` is set, at most *limit* samples are held: the sample past that empties the
    queue, :attr:`dropped` counts the samples emptied and :attr:`floor` keeps the newest source
    timestamp among them. Every dropped sample is in the server's history at or before the floor, and
    every sample after the drop is queued, so reading the history up to :meth:`edge` (never below the
    floor) and the queue from there loses nothing (:meth:`_Tracker._backfill`). The queue overflows
    where the tracker is behind: reading the history back after a long loss, or slower than the plant.
    """

    def __init__(self, limit: int) -> None:
        if limit < 1:
            raise ValueError(f"the queue's limit must be >= 1, got {limit!r}")
        self.limit = int(limit)
        self.items: list[tuple[str, Any]] = []
        self.spill = False
        self.floor: datetime | None = None
        self.dropped = 0

    def add(self, tag: str, dv: Any) -> None:
        self.items.append((tag, dv))
        if self.spill and len(self.items) > self.limit:
            newest = max((s for s in (_stamp(d) for _, d in self.items) if s is not None), default=None)
            if newest is not None and (self.floor is None or newest > self.floor):
                self.floor = newest
            self.dropped += len(self.items)
            log.info("%d samples queued while the tracker was behind were emptied: they are read from the history "
                     "instead (at most %d are queued)", len(self.items), self.limit)
            self.items = []

    def take(self) -> list[tuple[str, Any]]:
        items, self.items = self.items, []
        return items

    def edge(self, n_tags: int) -> datetime | None:
        """How far the history must be read: the newest of each tag's first queued sample, and the floor."""
        first: dict[str, datetime] = {}
        for tag, dv in self.items:
            if tag not in first and (s := _stamp(dv)) is not None:
                first[tag] = s
                if len(first) == n_tags:
                    break
        stamps = [*first.values(), *([self.floor] if self.floor is not None else [])]
        return max(stamps) if stamps else None

    def __len__(self) -> int:
        return len(self.items)


# --------------------------------------------------------------------------- the results server

class _Publisher:
    """The tracker's own OPC UA server: one variable per CSV column, updated row by row."""

    def __init__(self, url: str, columns: list[str]) -> None:
        self.url = url
        self.columns = [c for c in columns if c != "time"]
        self.server: Any = None
        self.nodes: dict[str, Any] = {}

    async def start(self) -> None:
        from asyncua import ua

        self.server = await make_server(self.url, name="trackingbox results")
        idx = await self.server.register_namespace(RESULTS_NAMESPACE)
        obj = await self.server.nodes.objects.add_object(idx, "TrackingBox")
        for c in self.columns:
            kind = ua.VariantType.String if c.startswith("mode:") else ua.VariantType.Double
            init = "" if kind == ua.VariantType.String else math.nan
            var = await obj.add_variable(ua.NodeId(c, idx), ua.QualifiedName(c, idx), ua.Variant(init, kind))
            self.nodes[c] = (var.nodeid, kind)
        await self.server.start()
        log.info("publishing %d result variables at %s", len(self.columns), self.url)

    async def publish(self, origin: datetime, rows: list[dict[str, str]]) -> None:
        from asyncua import ua

        for row in rows:
            stamp = at(origin, float(row["time"]))
            for c, (nodeid, kind) in self.nodes.items():
                raw = row.get(c, "")
                value: Any = raw if kind == ua.VariantType.String else (float(raw) if raw else math.nan)
                await self.server.write_attribute_value(nodeid, ua.DataValue(ua.Variant(value, kind),
                                                                             SourceTimestamp=stamp))

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.stop()


class _CsvTail:
    """Rows appended to ``tracking.csv`` since the last look."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.offset = 0
        self.header: list[str] | None = None

    def new_rows(self) -> list[dict[str, str]]:
        if not self.path.exists():
            return []
        with open(self.path, "rb") as fh:
            fh.seek(self.offset)
            data = fh.read()
        end = data.rfind(b"\n") + 1
        self.offset += end
        lines = list(csv.reader(io.StringIO(data[:end].decode("utf-8"))))
        if self.header is None and lines:
            self.header, lines = lines[0], lines[1:]
        return [dict(zip(self.header or [], row)) for row in lines]


# --------------------------------------------------------------------------- the tracker

class _Tracker:
    def __init__(self, spec: Spec, settings: LiveSettings, out_dir: Path, *, resume: bool,
                 progress: Callable[[int, int], None] | None) -> None:
        self.spec = spec
        self.settings = settings
        self.out = out_dir
        self.resume = resume
        self.progress = progress
        self.tags = list(spec.tags)
        self.ts = float(spec.sample_time)
        self.stale_after = float(spec.live.stale_after or 3.0 * self.ts)
        #: per tag: s of plant time without a sample before it is stale. Without [live] stale_after, a tag
        #: reported by exception ([data] heartbeat) may be quiet for as long as its gap rule allows
        #: (1.5 heartbeats, as the offline view takes it), any other for 3 sample times
        self.stale_limit = {tag: self.stale_after if spec.live.stale_after or spec.data.heartbeat_of(tag) is None
                            else heartbeat_max_gap(spec.data.heartbeat_of(tag)) for tag in self.tags}
        out_dir.mkdir(parents=True, exist_ok=True)
        self.live_json = out_dir / LIVE_NAME
        self.origin: datetime | None = None
        if resume and self.live_json.exists():
            try:
                doc = json.loads(self.live_json.read_text(encoding="utf-8"))
                self.origin = datetime.fromisoformat(doc["origin"])
            except (ValueError, KeyError, TypeError):
                raise CheckpointError(f"{self.live_json} is unreadable; run without --resume") from None
        self.record = _Record(out_dir / RECORD_NAME, self.tags, resume=resume)
        self.live_spec = replace(spec, measurements=self.record.path)
        #: the samples taken since the last batch, for the windowed stream: (tag, stamp, value or None)
        self.pending: list[tuple[str, datetime, float | None]] = []
        #: per tag: when (monotonic s) its newest sample came
        self.arrived: dict[str, float] = {}
        #: the rows around the loop's, window by window (memory flat in the run's length); None: the
        #: whole view of the record is rebuilt at every batch (a co-simulation twin, replayed from row 0)
        self.stream: LiveMeasurements | None = None
        if settings.windowed and livestream.usable(spec):
            self.stream = LiveMeasurements(self.live_spec, self.record.path,
                                           skip=float(spec.tracking.hold_until))
        self.loop: TrackingLoop | None = None
        self.samples_seen = 0
        self.backfilled = 0
        self.connections = 0
        self.stale: set[str] = set()
        self.stale_events = 0
        self.last_new = time.monotonic()
        self.tail = _CsvTail(out_dir / "tracking.csv")
        self.publisher = _Publisher(spec.live.publish, []) if spec.live.publish else None
        self.done = False
        #: the link as the live view shows it: connecting, connected, disconnected, stopped
        self.link = "connecting"
        self.link_since = time.time()
        self.link_error = ""
        self.lost = 0  # sessions lost
        self.status_path = out_dir / STATUS_NAME
        self.status_written = -math.inf
        self.last_new_wall: float | None = None

    # -- the status file (read by the live view, never waited for) ------------
    def status(self) -> dict[str, Any]:
        """The tracker's state now: the link, every tag's newest sample and staleness, the counts."""
        stamps = [s for s in self.record.last.values() if s is not None]
        clock = max(stamps) if stamps else None
        tags = {}
        for tag in self.tags:
            last, good = self.record.last[tag], self.record.good[tag]
            behind = (clock - last).total_seconds() if clock is not None and last is not None else None
            tags[tag] = {"last": last.isoformat() if last else None, "good": good.isoformat() if good else None,
                         "quality": None if last is None else "bad" if self.record.bad[tag] else "good",
                         "behind": behind, "stale": behind is not None and behind > self.stale_limit[tag],
                         "stale_after": self.stale_limit[tag]}
        loop = self.loop
        return {"version": 1, "written": time.time(), "pid": os.getpid(), "url": self.settings.url,
                "link": self.link, "link_since": self.link_since, "link_error": self.link_error,
                "connections": self.connections, "lost": self.lost, "samples": self.samples_seen,
                "backfilled": self.backfilled,
                "stale_events": self.stale_events, "rows": loop.k if loop is not None else 0,
                "origin": self.origin.isoformat() if self.origin else None,
                "plant_clock": clock.isoformat() if clock else None, "last_sample_wall": self.last_new_wall,
                "stale_after": self.stale_after, "sample_time": self.ts, "tags": tags}

    def write_status(self, *, force: bool = False) -> None:
        """Rewrite OUT/live_status.json (at most every STATUS_EVERY s unless *force*); never raises."""
        now = time.monotonic()
        if not force and now - self.status_written < STATUS_EVERY:
            return
        self.status_written = now
        tmp = self.status_path.with_name(f".{STATUS_NAME}.{os.getpid()}.tmp")
        try:
            tmp.write_text(json.dumps(self.status()), encoding="utf-8")
            os.replace(tmp, self.status_path)  # a reader sees the old file or the new one, whole
        except (OSError, ValueError) as exc:  # the view's file: never worth stopping the tracking for
            log.warning("cannot write %s (%s)", self.status_path, exc)

    def set_link(self, link: str, error: str = "") -> None:
        if link != self.link:
            self.link, self.link_since = link, time.time()
        self.link_error = error
        self.write_status(force=True)

    # -- samples ------------------------------------------------------------
    def take(self, tag: str, dv: Any, *, backfill: bool = False) -> bool:
        from asyncua import ua

        stamp = dv.SourceTimestamp or dv.ServerTimestamp
        if stamp is None:
            return False
        good = dv.StatusCode is None or dv.StatusCode.value == ua.StatusCodes.Good
        value = None
        if good and dv.Value is not None:
            try:
                value = float(dv.Value.Value)
            except (TypeError, ValueError):
                value = None
        if self.settings.start is not None and utc(stamp) < utc(self.settings.start):
            return False
        if not self.record.add(tag, stamp, value):
            return False
        self.pending.append((tag, utc(stamp), value))
        self.arrived[tag] = time.monotonic()
        self.samples_seen += 1
        self.backfilled += backfill
        self.last_new = time.monotonic()
        self.last_new_wall = time.time()
        return True

    # -- the tracking -------------------------------------------------------
    def _rows_ready(self) -> int:
        """Number of grid rows whose *next* sample every live (non-stale) tag has reached."""
        first = self.origin or self.record.first
        stamps = [s for s in self.record.last.values() if s is not None]
        if first is None or len(stamps) < len(self.tags):
            return 0
        if self.loop is None and any(g is None for g in self.record.good.values()):
            return 0  # a tag with bad samples only: nothing to start the twin from yet
        clock = max(stamps)
        live = []
        for tag, s in self.record.last.items():
            assert s is not None
            # stale: behind the plant's clock by more than its limit, and nothing from it for a while
            # (samples of one tag may come in a burst after another's, on a loaded machine)
            if (clock - s).total_seconds() > self.stale_limit[tag] and \
                    time.monotonic() - self.arrived.get(tag, -math.inf) > STALE_GRACE:
                if tag not in self.stale:
                    self.stale.add(tag)
                    self.stale_events += 1
                    log.warning("tag %r stale: nothing since %s (plant clock %s); its controller holds",
                                tag, s.isoformat(), clock.isoformat())
            else:
                if tag in self.stale:
                    self.stale.discard(tag)
                    log.info("tag %r is back", tag)
                live.append(s)
        limit = (min(live) - first).total_seconds()
        end = self.settings.stop_after
        if end is not None:
            if (clock - first).total_seconds() >= end - 1e-9 and (
                    limit >= end - 1e-9 or time.monotonic() - self.last_new > STALE_GRACE):
                # the plant's clock is at the run's end and every tag has come to it, or nothing has come
                # for a while (a quiet tag says nothing more before it; the other tags' samples of the
                # last row, read half-written from the server's history, have come): the rows to the
                # end are read as a file that ends there is read (no next sample to wait for)
                limit = end + self.ts
            limit = min(limit, end + self.ts)
        # rows k = 0 .. K-1 are ready when t_{k+1} = (k+1)·ts <= limit
        return max(0, int(math.floor(limit / self.ts + 1e-9)))

    def _view(self, rows: int) -> Any:
        hold = float(self.spec.tracking.hold_until)
        return MeasurementView.from_spec(self.live_spec, (0.0, (rows + 1) * self.ts), skip=hold)

    def _feed(self) -> None:
        """The samples taken since the last batch into the windowed stream (once the origin is known)."""
        if self.origin is None:
            return
        pending, self.pending = self.pending, []
        if self.stream is None:
            return
        origin = self.origin
        for tag, stamp, value in pending:
            self.stream.add(tag, (stamp - origin).total_seconds(), math.nan if value is None else value)

    def _resume_stream(self) -> None:
        """A resumed run's stream: the record so far read back (held until the loop has begun)."""
        assert self.stream is not None and self.origin is not None
        self.stream = LiveMeasurements(self.live_spec, self.record.path, skip=float(self.spec.tracking.hold_until))
        with open(self.record.path, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            next(reader, None)
            for tag, stamp, value in reader:
                t = (utc(datetime.fromisoformat(stamp)) - self.origin).total_seconds()
                self.stream.add(tag, t, float(value) if value else math.nan)
        self.pending = []  # the record holds them (taken before this batch)

    def _begin(self, ready: int) -> bool:
        """Make the loop (resumed from the checkpoint, or new): False while the twin cannot start yet."""
        ckpt = self.out / "checkpoint.json"
        if self.resume and ckpt.exists():
            # the loop resumes on the rows it was checkpointed with, then goes on
            rows_total = int(CheckpointFile(ckpt, self.out / "tracking.csv").read().get("rows_total", 0))
            if self.stream is not None:
                self._resume_stream()
                self.stream.grow(max(2, rows_total))
                self.loop = TrackingLoop(self.live_spec, out_dir=self.out, stream=self.stream)
            else:
                self.loop = TrackingLoop(self.live_spec, out_dir=self.out, view=self._view(max(1, rows_total - 1)))
            self.loop.begin(resume=True)
            if self.loop.k < ready:
                self._extend(ready)
            return True
        if self.stream is not None:
            if not self.done and not self.stream.inputs_valid(self._rows_known(ready)):
                return False  # an input has no valid value yet: the twin has nothing to start from
            self.stream.grow(self._rows_known(ready))
            self.loop = TrackingLoop(self.live_spec, out_dir=self.out, stream=self.stream)
        else:
            view = self._view(ready)
            if not self.done and not all(np.isfinite(view.values(tag)).any() for tag in self.spec.inputs):
                return False
            self.loop = TrackingLoop(self.live_spec, out_dir=self.out, view=view)
        self.loop.begin(resume=False)
        return True

    def _rows_known(self, ready: int) -> int:
        """Grid rows the stream holds for *ready* rows to run: one more (the next sample), not past the last sample."""
        assert self.origin is not None
        end = (max(s for s in self.record.last.values() if s is not None) - self.origin).total_seconds()
        return min(ready + 1, int(math.floor(end / self.ts + 1e-9)) + 1)

    def _extend(self, ready: int) -> None:
        assert self.loop is not None
        if self.stream is not None:
            self.stream.grow(self._rows_known(ready))
            self.loop.extend()
        else:
            self.loop.extend(self._view(ready))

    def advance(self) -> int:
        """Run every row that is ready (called in a worker thread); the number of rows run."""
        self.record.flush()
        ready = self._rows_ready()
        if self.origin is None and self.record.first is not None:
            self.origin = self.record.first
            write_text_atomic(self.live_json, json.dumps({"origin": self.origin.isoformat(),
                                                          "url": self.settings.url}) + "\n")
        self._feed()
        done = self.loop.k if self.loop is not None else 0
        if ready <= done or ready < 1:
            return 0
        if self.loop is None:
            if not self._begin(ready):
                return 0
        else:
            self._extend(ready)
        assert self.loop is not None
        n = ready - self.loop.k
        if n <= 0:
            return 0
        self.loop.run(max_steps=n, progress=self.progress)
        if self.stream is not None:
            self.stream.prune(self.loop.k)
        if self.settings.stop_after is not None and self.loop.k * self.ts >= self.settings.stop_after - 1e-9:
            self.done = True
        return n

    def finish(self) -> None:
        """At the end: write the last row whose samples all came (no next sample will come to step to)."""
        if self.loop is None:
            return
        self._feed()
        ready = self._rows_ready()
        if ready == self.loop.k and ready >= 1:
            self._extend(ready)
            self.loop.run()

    # -- connection ---------------------------------------------------------
    async def _client(self) -> Any:
        from asyncua import Client, ua
        from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

        live = self.spec.live
        # asyncua 2's connection supervisor probes the server every watchdog interval, with that long to
        # answer (1 s by default): on a loaded machine a live server was taken for lost (the soak, load 12
        # on 2 cores: 8 needless reconnections in 12 plant days); the request timeout is the probe's too
        client = Client(self.settings.url, timeout=self.settings.timeout, watchdog_intervall=self.settings.timeout)
        client.application_uri = CLIENT_URI
        if live.auth == "user":
            creds = self.settings.credentials
            assert creds is not None
            client.set_user(creds.user)
            client.set_password(creds.password)
        if live.security == "Basic256Sha256":
            assert live.certificate is not None and live.private_key is not None
            for what, path in (("certificate", live.certificate), ("private_key", live.private_key),
                               ("server_certificate", live.server_certificate)):
                if path is not None and not path.is_file():
                    raise LiveError(f"[live] {what} {path} in {self.spec.path} does not exist")
            mode = ua.MessageSecurityMode.SignAndEncrypt if live.mode == "SignAndEncrypt" \
                else ua.MessageSecurityMode.Sign
            await client.set_security(SecurityPolicyBasic256Sha256, str(live.certificate), str(live.private_key),
                                      server_certificate=str(live.server_certificate)
                                      if live.server_certificate else None, mode=mode)
        return client

    async def _session(self, client: Any) -> None:
        """One connected session: subscribe, read back what was missed, track until the link drops."""
        from asyncua import ua

        nodes = {}
        for tag in self.tags:
            try:
                nodes[tag] = client.get_node(self.spec.live.node(tag))
            except (ValueError, TypeError, ua.UaError) as exc:
                raise SpecError(f"[live] node id {self.spec.live.node(tag)!r} of tag {tag!r} in "
                                f"{self.spec.path} is not a node id: {exc}") from None
        inbox = _Inbox(QUEUE_LIMIT)
        inbox.spill = True
        by_node = {n.nodeid: tag for tag, n in nodes.items()}

        class Handler:
            def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
                inbox.add(by_node[node.nodeid], data.monitored_item.Value)

            def status_change_notification(self, status: Any) -> None:
                log.warning("subscription status from the server: %s", status)

        sub = await client.create_subscription(max(10.0, 1000.0 * self.settings.poll), Handler())
        # every write counts, also of an unchanged value (a new timestamp is a new sample): the
        # monitored items are made here with that filter (asyncua's subscribe_data_change sets none)
        requests = []
        for i, node in enumerate(nodes.values()):
            params = ua.MonitoringParameters(ClientHandle=_HANDLE0 + i, SamplingInterval=0.0, QueueSize=100000,
                                             DiscardOldest=True, Filter=ua.DataChangeFilter(
                                                 Trigger=ua.DataChangeTrigger.StatusValueTimestamp))
            requests.append(ua.MonitoredItemCreateRequest(
                ItemToMonitor=ua.ReadValueId(NodeId=node.nodeid, AttributeId=ua.AttributeIds.Value),
                MonitoringMode=ua.MonitoringMode.Reporting, RequestedParameters=params))
        handles = await sub.create_monitored_items(requests)
        for tag, h in zip(nodes, handles):
            if isinstance(h, ua.StatusCode):
                raise LiveError(f"cannot subscribe to tag {tag!r} at node {self.spec.live.node(tag)!r} on "
                                f"{self.settings.url}: {h.name}")
        covered = await self._backfill(nodes, inbox)
        while not self.done:
            if inbox.dropped != covered:  # the queue overflowed (the tracker fell behind): its samples from history
                covered = await self._backfill(nodes, inbox)
                continue
            items = inbox.take()
            for tag, dv in items:
                self.take(tag, dv)
            # the samples taken, written before the rows they make (a batch may take a while)
            self.write_status(force=bool(items))
            await asyncio.to_thread(self.advance)
            self.write_status()
            await self._publish()
            if self._idle():
                return
            await client.check_connection()
            await asyncio.sleep(self.settings.poll)

    async def _backfill(self, nodes: dict[str, Any], inbox: _Inbox) -> int:
        """Read what the server's history holds since each tag's last sample (or the start), a stretch of
        plant time at a time (BACKFILL_ROWS samples), running the rows it makes as it goes: a long loss
        is read back with the memory of one stretch, every tag as far as the others. The subscription's
        samples meanwhile wait in *inbox*, at most QUEUE_LIMIT of them (see :class:`_Inbox`). Returns
        the inbox's count of dropped samples that the history read covers (a drop after it: read again)."""
        from asyncua import ua

        since = {tag: self.record.last[tag] or self.settings.start or self.origin for tag in nodes}
        since = {tag: utc(s) for tag, s in since.items() if s is not None}
        if not since:
            return inbox.dropped
        step = timedelta(seconds=BACKFILL_ROWS * self.ts)
        a = min(since.values())
        failed: set[str] = set()

        async def read(tag: str, end: datetime | None) -> list[Any]:
            last = self.record.last[tag]
            if last is not None and end is not None and utc(last) >= end:
                return []  # this tag is past the stretch already
            # from its own newest sample: read while the server was writing, it may end before the stretch
            start = utc(last) if last is not None else since[tag]
            try:
                history = await nodes[tag].read_raw_history(starttime=start, endtime=end)
            except ua.UaError as exc:
                log.warning("no history of %r from %s (%s): samples missed while disconnected are lost", tag,
                            self.settings.url, exc)
                failed.add(tag)
                return []
            return sorted(history, key=lambda d: d.SourceTimestamp or d.ServerTimestamp)

        async def stretch(end: datetime | None) -> int:
            # every tag's samples of the stretch are read before any is taken: a link lost half way
            # leaves no tag further on than the others (they would look stale), the stretch is read again
            got = {tag: await read(tag, end) for tag in since if tag not in failed}
            return sum(self.take(tag, dv, backfill=True) for tag, values in got.items() for dv in values)

        # Where the subscription's samples begin is inbox.edge(): the history is read up to there, the
        # queue has the rest (it grows while the history is read, and is emptied past its limit: the
        # edge is then the newest sample dropped, and moves on with the samples queued after it)
        covered = inbox.dropped
        while not self.done:
            # the edge, and the drops it covers (one during the read below is left to the next call)
            edge, covered = inbox.edge(len(nodes)), inbox.dropped
            # past the edge, every tag once more up to it (one read as the server wrote may stop short of it)
            past = edge is not None and a > edge
            got = await stretch(edge if past else a + step)
            if got:
                self.write_status()
                await asyncio.to_thread(self.advance)
                self.write_status()
            if past or (not got and (edge is None or a + step >= edge)):
                break  # the queue goes on from here (nothing in this stretch: the rest, if any, below)
            a = a + step  # (a quiet stretch before the queue's: on)
        if not self.done and inbox.edge(len(nodes)) is None:
            await stretch(None)  # nothing queued, nothing dropped: the server is quiet, or just begun
        return covered

    def _idle(self) -> bool:
        t = self.settings.idle_timeout
        if t is not None and time.monotonic() - self.last_new > t:
            log.info("no new sample for %g s: stopping", t)
            self.done = True
        return self.done

    async def _publish(self) -> None:
        if self.publisher is None or self.loop is None or self.origin is None:
            return
        if self.publisher.server is None:
            # the CSV's columns, the tracked parameters' bands (parameter_lo:/parameter_hi:<name>) included
            self.publisher.columns = [c for c in self.loop.output.columns if c != "time"]
            await self.publisher.start()
        rows = self.tail.new_rows()
        if rows:
            await self.publisher.publish(self.origin, rows)

    async def run(self) -> None:
        from asyncua import ua

        if self.spec.live.auth == "user" and self.settings.credentials is None:
            raise LiveError(f"[live] auth = \"user\" in {self.spec.path}: give the user name and password in "
                            "TRACKINGBOX_OPCUA_USER and TRACKINGBOX_OPCUA_PASSWORD or in a file "
                            "(--credentials FILE); anonymous access is not used")
        wait = self.settings.backoff[0]
        try:
            while not self.done:
                client = await self._client()
                try:
                    await asyncio.wait_for(client.connect(), timeout=self.settings.timeout * 2)
                except ua.UaStatusCodeError as exc:
                    if _refused(exc):
                        raise LiveError(f"{self.settings.url} refused the session ({type(exc).__name__}: "
                                        f"{exc}); check the credentials"
                                        + (" (this spec connects anonymously; [live] auth = \"user\" to log in)"
                                           if self.spec.live.auth == "anonymous" else "")) from None
                    log.warning("cannot connect to %s (%s); retrying in %g s", self.settings.url, exc, wait)
                    self.set_link(self.link, str(exc))
                except (OSError, asyncio.TimeoutError, ConnectionError, ua.UaError) as exc:
                    if "No matching endpoints" in str(exc):  # a security mismatch: retrying will not help
                        raise LiveError(f"{self.settings.url} offers no endpoint with this spec's security "
                                        f"({self.spec.live.security or 'None'}, {self.spec.live.mode}): set "
                                        f"[live] security and mode in {self.spec.path} to what the server "
                                        "offers") from None
                    log.warning("cannot connect to %s (%s); retrying in %g s", self.settings.url,
                                exc or type(exc).__name__, wait)
                    self.set_link(self.link, str(exc) or type(exc).__name__)
                else:
                    self.connections += 1
                    log.info("connected to %s (connection %d)", self.settings.url, self.connections)
                    self.set_link("connected")
                    wait = self.settings.backoff[0]
                    try:
                        await self._session(client)
                    except (OSError, asyncio.TimeoutError, ConnectionError, ua.UaError) as exc:
                        log.warning("lost %s (%s); reconnecting in %g s", self.settings.url,
                                    exc or type(exc).__name__, wait)
                        self.lost += 1
                        self.set_link("disconnected", str(exc) or type(exc).__name__)
                    finally:
                        try:
                            await asyncio.wait_for(client.disconnect(), timeout=1.0)
                        except Exception:  # noqa: BLE001 - the link is gone already
                            client.disconnect_socket()
                if self.done or self._idle():
                    break
                await asyncio.sleep(wait)
                wait = min(2.0 * wait, self.settings.backoff[1])
                # samples taken while disconnected cannot come: run what is ready
                await asyncio.to_thread(self.advance)
                self.write_status()
                await self._publish()
        finally:
            self.record.close()
            self.set_link("stopped")
            if self.publisher is not None:
                await self.publisher.stop()


def _refused(exc: Exception) -> bool:
    """True for a session the server refused for who the client is (not worth retrying)."""
    name = type(exc).__name__
    return any(s in name for s in ("Identity", "UserAccessDenied", "Certificate", "SecurityPolicyRejected",
                                   "SecurityChecksFailed"))


def track_live(spec: Spec, settings: LiveSettings, *, out_dir: str | Path, resume: bool = False,
               progress: Callable[[int, int], None] | None = None) -> LiveResult:
    """Track the plant live over OPC UA until stopped; see the module docstring.

    Parameters
    ----------
    spec : trackingbox.spec.Spec
        A spec with ``[[pairs]]`` (and ``[live]`` where the defaults do not fit).
    settings : LiveSettings
    out_dir : path
        ``tracking.csv``, ``checkpoint.json``, ``result.json``, ``live_measurements.csv``, ``live.json``.
    resume : bool
        Continue a run in *out_dir* (its record, checkpoint and time origin).
    progress : callable, optional
        ``progress(rows_done, rows_known)``.

    Returns
    -------
    LiveResult

    Raises
    ------
    LiveError
        Credentials missing or refused, a tag that cannot be subscribed.
    SpecError, DataError, CheckpointError
        As for :func:`trackingbox.tracking.runtime.track`.
    """
    if not spec.pairs:
        raise SpecError(f"spec {spec.path} has no [[pairs]]; run `trackingbox pair` first or add them")
    check_against_fmu(spec)
    tracker = _Tracker(spec, settings, Path(out_dir), resume=resume, progress=progress)
    try:
        asyncio.run(tracker.run())
        tracker.finish()
    except KeyboardInterrupt:
        log.info("stopped by the user")
    finally:
        if tracker.loop is not None:
            tracker.loop.close()
    if tracker.loop is None:
        raise DataError(f"no complete sample of every tag came from {settings.url} "
                        f"({tracker.samples_seen} samples): nothing was tracked")
    result = tracker.loop.result()
    return LiveResult(result, tracker.origin or datetime.now(), tracker.record.count, tracker.backfilled,
                      tracker.connections, tracker.stale_events)
