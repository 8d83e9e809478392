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
``mode:<tag>`` and the band ``parameter_lo:<name>`` / ``parameter_hi:<name>``
(the CSV's columns), updated after every row with the row's plant time as
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
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import CheckpointError, DataError, LiveError, SpecError
from ..io import write_text_atomic
from .opcua import CLIENT_URI, RESULTS_NAMESPACE, Credentials, at, check_endpoint, make_server, utc

if TYPE_CHECKING:
    from ..spec import Spec
    from ..tracking.runtime import TrackingLoop, TrackingResult

log = logging.getLogger(__name__)

__all__ = ["LiveSettings", "LiveResult", "track_live", "RECORD_NAME", "LIVE_NAME"]

#: The samples received, as a historian's long form.
RECORD_NAME = "live_measurements.csv"
#: The run's time origin and endpoint (for --resume).
LIVE_NAME = "live.json"


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
    """

    url: str
    credentials: Credentials | None = None
    start: datetime | None = None
    stop_after: float | None = None
    idle_timeout: float | None = None
    backoff: tuple[float, float] = (0.5, 30.0)
    poll: float = 0.1
    timeout: float = 4.0

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
                self.first = t if self.first is None or t < self.first else self.first
                self.count += 1

    def add(self, tag: str, stamp: datetime, value: float | None) -> bool:
        """Record one sample (``None``: bad quality, not recorded); False if not newer than the last."""
        stamp = utc(stamp)
        last = self.last[tag]
        if last is not None and stamp <= last:
            return False
        self.last[tag] = stamp
        if value is None or not math.isfinite(value):
            return True
        if self.first is None or stamp < self.first:
            self.first = stamp
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

    # -- samples ------------------------------------------------------------
    def take(self, tag: str, dv: Any, *, backfill: bool = False) -> None:
        from asyncua import ua

        stamp = dv.SourceTimestamp or dv.ServerTimestamp
        if stamp is None:
            return
        good = dv.StatusCode_ is None or dv.StatusCode_.value == ua.StatusCodes.Good
        value = None
        if good and dv.Value is not None:
            try:
                value = float(dv.Value.Value)
            except (TypeError, ValueError):
                value = None
        if self.settings.start is not None and utc(stamp) < utc(self.settings.start):
            return
        if self.record.add(tag, stamp, value):
            self.samples_seen += 1
            self.backfilled += backfill
            self.last_new = time.monotonic()

    # -- the tracking -------------------------------------------------------
    def _rows_ready(self) -> int:
        """Number of grid rows whose *next* sample every live (non-stale) tag has reached."""
        first = self.origin or self.record.first
        stamps = [s for s in self.record.last.values() if s is not None]
        if first is None or len(stamps) < len(self.tags):
            return 0
        clock = max(stamps)
        live = []
        for tag, s in self.record.last.items():
            assert s is not None
            if (clock - s).total_seconds() > self.stale_after:
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
        if self.settings.stop_after is not None:
            limit = min(limit, self.settings.stop_after + self.ts)
        # rows k = 0 .. K-1 are ready when t_{k+1} = (k+1)·ts <= limit
        return max(0, int(math.floor(limit / self.ts + 1e-9)))

    def _view(self, rows: int) -> Any:
        from ..data import MeasurementView

        hold = float(self.spec.tracking.hold_until)
        return MeasurementView.from_spec(self.live_spec, (0.0, (rows + 1) * self.ts), skip=hold)

    def advance(self) -> int:
        """Run every row that is ready (called in a worker thread); the number of rows run."""
        from ..tracking.runtime import TrackingLoop

        self.record.flush()
        ready = self._rows_ready()
        if self.origin is None and self.record.first is not None:
            self.origin = self.record.first
            write_text_atomic(self.live_json, json.dumps({"origin": self.origin.isoformat(),
                                                          "url": self.settings.url}) + "\n")
        done = self.loop.k if self.loop is not None else 0
        if ready <= done or ready < 1:
            return 0
        if self.loop is None:
            ckpt = self.out / "checkpoint.json"
            if self.resume and ckpt.exists():
                from ..checkpoint import CheckpointFile

                # the loop resumes on the view it was checkpointed with (its rows), then extends
                rows_total = int(CheckpointFile(ckpt, self.out / "tracking.csv").read().get("rows_total", 0))
                self.loop = TrackingLoop(self.live_spec, out_dir=self.out, view=self._view(max(1, rows_total - 1)))
                self.loop.begin(resume=True)
                if self.loop.k < ready:
                    self.loop.extend(self._view(ready))
            else:
                self.loop = TrackingLoop(self.live_spec, out_dir=self.out, view=self._view(ready))
                self.loop.begin(resume=False)
        else:
            self.loop.extend(self._view(ready))
        n = ready - self.loop.k
        if n <= 0:
            return 0
        self.loop.run(max_steps=n, progress=self.progress)
        if self.settings.stop_after is not None and self.loop.k * self.ts >= self.settings.stop_after - 1e-9:
            self.done = True
        return n

    def finish(self) -> None:
        """At the end: write the last row whose samples all came (no next sample will come to step to)."""
        if self.loop is None:
            return
        ready = self._rows_ready()
        if ready == self.loop.k and ready >= 1:
            self.loop.extend(self._view(ready))
            self.loop.run()

    # -- connection ---------------------------------------------------------
    async def _client(self) -> Any:
        from asyncua import Client, ua
        from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

        live = self.spec.live
        client = Client(self.settings.url, timeout=self.settings.timeout)
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
        queue: list[tuple[str, Any]] = []
        by_node = {n.nodeid: tag for tag, n in nodes.items()}

        class Handler:
            def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
                queue.append((by_node[node.nodeid], data.monitored_item.Value))

            def status_change_notification(self, status: Any) -> None:
                log.warning("subscription status from the server: %s", status)

        sub = await client.create_subscription(max(10.0, 1000.0 * self.settings.poll), Handler())
        # every write counts, also of an unchanged value (a new timestamp is a new sample);
        # asyncua 1.1's public subscribe_data_change takes no filter, hence _subscribe (the version is pinned)
        handles = await sub._subscribe(list(nodes.values()), ua.AttributeIds.Value,
                                       mfilter=ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValueTimestamp),
                                       queuesize=100000, sampling_interval=0.0)
        for tag, h in zip(nodes, handles if isinstance(handles, list) else [handles]):
            if isinstance(h, ua.StatusCode):
                raise LiveError(f"cannot subscribe to tag {tag!r} at node {self.spec.live.node(tag)!r} on "
                                f"{self.settings.url}: {h.name}")
        # what the server's history holds since the last sample of each tag (or the start)
        for tag, node in nodes.items():
            since = self.record.last[tag] or self.settings.start
            if since is None and self.origin is None:
                continue
            try:
                history = await node.read_raw_history(starttime=since or self.origin, endtime=None)
            except ua.UaError as exc:
                log.warning("no history of %r from %s (%s): samples missed while disconnected are lost", tag,
                            self.settings.url, exc)
                continue
            for dv in sorted(history, key=lambda d: d.SourceTimestamp):
                self.take(tag, dv, backfill=True)
        while not self.done:
            items, queue[:] = list(queue), []
            for tag, dv in items:
                self.take(tag, dv)
            await asyncio.to_thread(self.advance)
            await self._publish()
            if self._idle():
                return
            await client.check_connection()
            await asyncio.sleep(self.settings.poll)

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
                except (OSError, asyncio.TimeoutError, ConnectionError, ua.UaError) as exc:
                    if "No matching endpoints" in str(exc):  # a security mismatch: retrying will not help
                        raise LiveError(f"{self.settings.url} offers no endpoint with this spec's security "
                                        f"({self.spec.live.security or 'None'}, {self.spec.live.mode}): set "
                                        f"[live] security and mode in {self.spec.path} to what the server "
                                        "offers") from None
                    log.warning("cannot connect to %s (%s); retrying in %g s", self.settings.url,
                                exc or type(exc).__name__, wait)
                else:
                    self.connections += 1
                    log.info("connected to %s (connection %d)", self.settings.url, self.connections)
                    wait = self.settings.backoff[0]
                    try:
                        await self._session(client)
                    except (OSError, asyncio.TimeoutError, ConnectionError, ua.UaError) as exc:
                        log.warning("lost %s (%s); reconnecting in %g s", self.settings.url,
                                    exc or type(exc).__name__, wait)
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
                await self._publish()
        finally:
            self.record.close()
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
    from ..spec import check_against_fmu

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
