"""A plant historian's export of a dense simulated frame (DCS-like measurement history).

A mill's measurements do not come as one table sampled on a common grid. A DCS
scans each tag at its own rate (1..60 s) and the timestamps jitter. The historian
archives a value only on *exception*: when it has moved more than the tag's dead
band from the last archived value, or when the last archived value is older than
the tag's heartbeat (maximum interval, typically 10..15 min). A steady tag is
therefore logged rarely. When the link to a controller is lost, the historian
writes a bad-quality event and nothing more until the link is back; the first scan
after that is archived unconditionally.

:func:`export_history` turns a dense frame (``time`` in s, one column per tag, as
a bench simulates it, sensor noise included) into that record, deterministically
for a given seed. :class:`HistorianExport` writes it as CSV in two forms:

``long`` (``tag,time,value``, sorted by tag and time: how historians export raw
archived values)
    ISO 8601 UTC timestamps with offset and millisecond resolution; an empty
    ``value`` is a bad-quality event (communication loss from that time until the
    tag's next record). :func:`trackingbox.data.read_table` reads this form and
    keeps the bad-quality events (``df.attrs["breaks"]``), so the data layer
    never bridges a communication loss.
``wide`` (``time`` then one column per tag)
    One row per time at which any tag was archived; a tag's cell is empty where it
    was not archived. Bad-quality events cannot be told from "not archived" in this
    form; a communication loss shows only as silence longer than the heartbeat.

The data layer's side: give the tags' heartbeats to the spec (``[data] heartbeat``,
:meth:`HistorianExport.heartbeats`); a tag with a heartbeat is reconstructed by
holding its last archived value (exact to within its dead band) and is missing
only where it was silent longer than 1.5 x its heartbeat, or after a bad-quality
event.

Examples
--------
>>> frame = pd.DataFrame({"time": np.arange(0.0, 3601.0), "LI": np.r_[np.full(1800, 1.0), np.full(1801, 1.5)]})
>>> settings = HistorianSettings(default=TagSettings(scan=5.0, jitter=0.0, deadband=0.01, heartbeat=600.0, phase=0.0),
...                              outages_per_day=0.0)
>>> h = export_history(frame, settings)
>>> h.records["time"].tolist()  # first scan, heartbeats, the step, heartbeats
[0.0, 600.0, 1200.0, 1800.0, 2400.0, 3000.0, 3600.0]
>>> h.records["value"].tolist()
[1.0, 1.0, 1.0, 1.5, 1.5, 1.5, 1.5]
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..errors import DataError, SpecError, did_you_mean
from ..io import atomic_path

log = logging.getLogger(__name__)

Form = Literal["long", "wide"]

#: Longest scan interval a DCS tag has here, and the shortest (s).
SCAN_RANGE = (1.0, 60.0)


@dataclass(frozen=True)
class TagSettings:
    """How the DCS scans one tag and the historian archives it.

    Attributes
    ----------
    scan : float
        Scan interval (s), 1..60.
    jitter : float
        Each scan's timestamp moves by a uniform amount within ``+- jitter * scan``;
        0 <= jitter < 0.5 (timestamps stay in order).
    deadband : float
        Exception dead band in the tag's unit (>= 0): a scan is archived when it
        differs from the last archived value by more than this. 0 archives every scan.
    heartbeat : float
        Maximum interval between archived values (s, >= scan): a scan at least this
        long after the last archived value is archived whatever its value.
    phase : float or None
        Time of the first scan after the frame's start (s, 0 <= phase < scan);
        None: drawn at random.
    """

    scan: float = 10.0
    jitter: float = 0.2
    deadband: float = 0.0
    heartbeat: float = 900.0
    phase: float | None = None

    def check(self, tag: str) -> None:
        """Raise :class:`~trackingbox.errors.SpecError` naming *tag* if a setting is out of range."""
        problems = []
        lo, hi = SCAN_RANGE
        if not (lo <= self.scan <= hi):
            problems.append(f"scan = {self.scan!r} s is outside {lo:g}..{hi:g} s")
        if not (0.0 <= self.jitter < 0.5):
            problems.append(f"jitter = {self.jitter!r} must be in [0, 0.5) (a fraction of the scan)")
        if not (self.deadband >= 0.0 and math.isfinite(self.deadband)):
            problems.append(f"deadband = {self.deadband!r} must be a finite number >= 0")
        if not (math.isfinite(self.heartbeat) and self.heartbeat >= self.scan):
            problems.append(f"heartbeat = {self.heartbeat!r} s must be finite and at least the scan ({self.scan:g} s)")
        if self.phase is not None and not (0.0 <= self.phase < self.scan):
            problems.append(f"phase = {self.phase!r} s must be in [0, scan)")
        if problems:
            raise SpecError(f"historian settings of tag {tag!r}: " + "; ".join(problems))


@dataclass(frozen=True)
class HistorianSettings:
    """Settings of :func:`export_history`.

    Attributes
    ----------
    tags : mapping of str to TagSettings
        Per-tag settings; tags not listed use *default*.
    default : TagSettings
        Settings of the tags not in *tags*.
    start : str
        ISO 8601 timestamp of the frame's ``time = 0`` (with an offset; written in UTC).
    outages_per_day : float
        Mean number of communication losses per day (Poisson).
    outage_duration : (float, float)
        Shortest and longest loss (s); each is uniform in between.
    outage_all_tags : float
        Probability that a loss takes every tag (the interface node); otherwise it
        takes one tag chosen at random.
    seed : int
        Seed of the random generator: the same frame and settings give the same export.
    """

    tags: Mapping[str, TagSettings] = field(default_factory=dict)
    default: TagSettings = field(default_factory=TagSettings)
    start: str = "2026-01-05T06:00:00+00:00"
    outages_per_day: float = 2.0
    outage_duration: tuple[float, float] = (300.0, 2700.0)
    outage_all_tags: float = 0.5
    seed: int = 0

    def for_tag(self, tag: str) -> TagSettings:
        """The settings of *tag*."""
        return self.tags.get(tag, self.default)

    def start_time(self) -> pd.Timestamp:
        """:attr:`start` as a UTC timestamp; :class:`~trackingbox.errors.SpecError` if it is not ISO 8601 with an offset."""
        try:
            ts = pd.Timestamp(self.start)
        except (ValueError, TypeError):
            raise SpecError(f"historian start {self.start!r} is not an ISO 8601 timestamp") from None
        if ts.tzinfo is None:
            raise SpecError(f"historian start {self.start!r} has no UTC offset (write e.g. '+00:00')")
        return ts.tz_convert("UTC")


@dataclass(frozen=True)
class Outage:
    """A communication loss: no values of *tags* in ``[start, stop)`` (s from the frame's start)."""

    start: float
    stop: float
    tags: tuple[str, ...]


@dataclass(frozen=True)
class HistorianExport:
    """What the historian archived: :func:`export_history`'s result.

    Attributes
    ----------
    records : pandas.DataFrame
        ``tag``, ``time`` (s from *start*, millisecond resolution) and ``value``
        (NaN: a bad-quality event, the start of a communication loss), sorted by tag
        and time.
    start : pandas.Timestamp
        UTC time of ``time = 0``.
    outages : tuple of Outage
        The communication losses drawn.
    settings : HistorianSettings
        The settings used.
    """

    records: pd.DataFrame = field(repr=False)
    start: pd.Timestamp
    outages: tuple[Outage, ...]
    settings: HistorianSettings = field(repr=False)

    @property
    def tags(self) -> list[str]:
        """The exported tags, in the frame's column order."""
        return list(dict.fromkeys(self.records["tag"]))

    def timestamps(self, seconds: npt.ArrayLike) -> list[str]:
        """ISO 8601 UTC strings (millisecond resolution, ``+00:00``) of *seconds* from :attr:`start`."""
        s = np.round(np.asarray(seconds, dtype=float), 3)
        stamps = self.start + pd.to_timedelta(s, unit="s")
        return [t.isoformat(timespec="milliseconds") for t in stamps]

    def long(self) -> pd.DataFrame:
        """The ``tag,time,value`` table with ISO 8601 times (NaN value: bad quality)."""
        return pd.DataFrame({"tag": self.records["tag"].to_numpy(),
                             "time": self.timestamps(self.records["time"]),
                             "value": self.records["value"].to_numpy()})

    def wide(self) -> pd.DataFrame:
        """One row per archive time, one column per tag (empty where not archived; bad events dropped)."""
        good = self.records[np.isfinite(self.records["value"].to_numpy())]
        table = good.pivot(index="time", columns="tag", values="value").reindex(columns=self.tags)
        table = table.sort_index()
        out = pd.DataFrame({"time": self.timestamps(table.index.to_numpy())})
        for tag in self.tags:
            out[tag] = table[tag].to_numpy()
        return out

    def write(self, path: str | Path, form: Form = "long") -> Path:
        """Write the export as CSV in *form* (atomically) and return the path."""
        if form not in ("long", "wide"):
            raise SpecError(f"historian export form must be 'long' or 'wide', not {form!r}")
        table = self.long() if form == "long" else self.wide()
        path = Path(path)
        with atomic_path(path) as tmp:
            table.to_csv(tmp, index=False, float_format="%.9g", na_rep="")
        log.info("historian export (%s form, %d records, %d outages) written to %s",
                 form, len(self.records), len(self.outages), path)
        return path

    def heartbeats(self) -> dict[str, float]:
        """Tag -> heartbeat (s): what the spec's ``[data.heartbeat]`` table needs."""
        return {tag: float(self.settings.for_tag(tag).heartbeat) for tag in self.tags}

    def to_json(self) -> dict[str, Any]:
        """Per-tag record counts and intervals, and the communication losses."""
        tags: dict[str, Any] = {}
        for tag, group in self.records.groupby("tag", sort=False):
            t = group["time"].to_numpy()
            v = group["value"].to_numpy()
            good = t[np.isfinite(v)]
            d = np.diff(good)
            s = self.settings.for_tag(str(tag))
            tags[str(tag)] = {
                "records": int(good.size), "bad_events": int(np.count_nonzero(~np.isfinite(v))),
                "median_interval": float(np.median(d)) if d.size else None,
                "longest_interval": float(d.max()) if d.size else None,
                "scan": s.scan, "jitter": s.jitter, "deadband": s.deadband, "heartbeat": s.heartbeat,
            }
        return {"start": self.start.isoformat(), "tags": tags,
                "outages": [{"start": o.start, "stop": o.stop, "tags": list(o.tags)} for o in self.outages]}


def _draw_outages(rng: np.random.Generator, t_first: float, t_last: float, tags: Sequence[str],
                  settings: HistorianSettings) -> tuple[Outage, ...]:
    days = (t_last - t_first) / 86400.0
    if settings.outages_per_day <= 0 or days <= 0:
        return ()
    lo, hi = settings.outage_duration
    if not (0 < lo <= hi):
        raise SpecError(f"historian outage_duration {settings.outage_duration!r} must be (shortest, longest) "
                        "with 0 < shortest <= longest (s)")
    n = int(rng.poisson(settings.outages_per_day * days))
    outages = []
    for _ in range(n):
        start = float(rng.uniform(t_first, t_last))
        duration = float(rng.uniform(lo, hi))
        everyone = bool(rng.random() < settings.outage_all_tags)
        hit = tuple(tags) if everyone else (str(tags[int(rng.integers(len(tags)))]),)
        outages.append(Outage(start=start, stop=min(start + duration, t_last), tags=hit))
    return tuple(sorted(outages, key=lambda o: o.start))


def _archive(times: npt.NDArray[np.float64], values: npt.NDArray[np.float64], down: npt.NDArray[np.bool_],
             deadband: float, heartbeat: float) -> tuple[list[float], list[float]]:
    """Exception reporting over one tag's scans; a bad event at the first scan of each outage."""
    out_t: list[float] = []
    out_v: list[float] = []
    last_t = -math.inf
    last_v = math.nan  # NaN: nothing archived since the start or the last outage -> archive the next scan
    was_down = False
    for t, v, d in zip(times.tolist(), values.tolist(), down.tolist()):
        if d:
            if not was_down:
                out_t.append(t)
                out_v.append(math.nan)
                last_v = math.nan
            was_down = True
            continue
        was_down = False
        if last_v != last_v or abs(v - last_v) > deadband or t - last_t >= heartbeat - 1e-9:
            out_t.append(t)
            out_v.append(v)
            last_t, last_v = t, v
    return out_t, out_v


def export_history(frame: pd.DataFrame, settings: HistorianSettings | None = None, *,
                   tags: Sequence[str] | None = None) -> HistorianExport:
    """Archive a dense simulated *frame* the way a plant historian would.

    For each tag: scan times ``phase + k * scan`` (a random phase per tag) moved by
    the jitter and rounded to the millisecond; the value at each scan is the
    frame's, linearly interpolated; scans inside a communication loss of the tag
    are lost (one bad-quality event at the first of them); the remaining scans go
    through exception reporting (dead band and heartbeat, :class:`TagSettings`).

    Parameters
    ----------
    frame
        ``time`` (s, increasing) and one column per tag, finite values, sampled
        at least as densely as the fastest scan.
    settings
        Scan, jitter, dead band and heartbeat per tag; communication losses; seed.
    tags
        Columns to export (default: all but ``time``).

    Returns
    -------
    HistorianExport

    Raises
    ------
    DataError
        No ``time`` column, time not increasing, an unknown tag, non-finite values.
    SpecError
        A setting out of range (named with its tag).
    """
    settings = settings or HistorianSettings()
    if "time" not in frame.columns:
        raise DataError(f"historian export: the frame has no 'time' column{did_you_mean('time', list(frame.columns))}")
    t = frame["time"].to_numpy(dtype=float)
    if t.size < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise DataError("historian export: the frame's 'time' must be finite and strictly increasing, "
                        "with at least two rows")
    names = [c for c in frame.columns if c != "time"] if tags is None else list(tags)
    for tag in names:
        if tag not in frame.columns:
            raise DataError(f"historian export: tag {tag!r} is not a column of the frame"
                            f"{did_you_mean(tag, [c for c in frame.columns if c != 'time'])}")
    for tag in settings.tags:
        if tag not in names:
            raise SpecError(f"historian settings name tag {tag!r}, which is not exported{did_you_mean(tag, names)}")
    for tag in names:
        settings.for_tag(tag).check(tag)
    start = settings.start_time()
    rng = np.random.default_rng(settings.seed)
    t_first, t_last = float(t[0]), float(t[-1])
    outages = _draw_outages(rng, t_first, t_last, names, settings)
    parts = []
    for tag in names:
        s = settings.for_tag(tag)
        y = frame[tag].to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(y))
        if bad.size:
            raise DataError(f"historian export: tag {tag!r} has non-finite values, first at t = {t[bad[0]]:g} s")
        drawn = float(rng.uniform(0.0, s.scan))  # drawn even when fixed: other tags keep their draws
        phase = drawn if s.phase is None else float(s.phase)
        nominal = t_first + phase + s.scan * np.arange(int(math.floor((t_last - t_first - phase) / s.scan)) + 1)
        times = np.round(nominal + rng.uniform(-s.jitter * s.scan, s.jitter * s.scan, nominal.size), 3)
        times = times[(times >= t_first) & (times <= t_last)]
        values = np.interp(times, t, y)
        down = np.zeros(times.size, dtype=bool)
        for o in outages:
            if tag in o.tags:
                down |= (times >= o.start) & (times < o.stop)
        out_t, out_v = _archive(times, values, down, s.deadband, s.heartbeat)
        parts.append(pd.DataFrame({"tag": tag, "time": out_t, "value": out_v}))
    records = pd.concat(parts, ignore_index=True)
    log.debug("historian export: %d tags, %d records, %d outages", len(names), len(records), len(outages))
    return HistorianExport(records=records, start=start, outages=outages, settings=settings)
