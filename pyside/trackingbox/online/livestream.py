"""The live record's samples around the tracking loop's row, window by window: memory flat in the run's length.

The online mode used to rebuild the whole measurement view from
``live_measurements.csv`` at every batch of rows: its time and memory grew
with the run (a 30-day evaporator record is 1.3 million samples). A
:class:`LiveMeasurements` instead holds the samples received per tag for the
stretch the loop can still reach, and hands the loop (made with
``TrackingLoop(..., stream=...)``, driven with ``extend()``) the rows around
its own as :class:`~trackingbox.data.MeasurementView` windows, as
:class:`trackingbox.stream.WindowedMeasurements` does for a file. Each window is
made by the functions the whole view is made by
(:func:`~trackingbox.data.resample`, :func:`~trackingbox.data.lay_masks`) from
every sample that can reach it:

* a tag's value at a grid point depends only on its valid samples within the
  tag's gap limit of the point (farther ones make the point a gap either way)
  and the bad-quality events after the last of them: the samples within the
  gap limit plus one sample time of the window are kept;
* the stoppage and input-gap masks reach ``settle`` s forward: the window is
  laid from that many rows before its first;
* an input's hold starts from its last valid grid value before the window
  (kept from the windows before), or its first valid value.

What the whole view takes from the whole file is taken from the samples so far:
a tag's gap limit without ``[data] max_gap`` or a heartbeat (2.5 x the median
of its sampling intervals, counted as the samples come: exactly, or past 20,000
distinct values to 4 significant digits, see :class:`_Intervals`), and the 1st and 99th
percentiles of the pairs' variables and levels (from the rows the loop starts
with), as the rebuilt view took them. Samples older than the stretch the loop
can reach are dropped (:meth:`LiveMeasurements.prune`); only counters and a
few last values per tag are kept from them.

A twin that must be replayed from the start (co-simulation, whose states are
not accessible) needs the inputs from row 0: such a run takes the whole view
(:func:`usable`).
"""
from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd

from ..data.series import GAP_FACTOR, heartbeat_max_gap, resample
from ..data.view import MeasurementView, lay_masks, view_tags
from ..errors import DataError, TrackingError
from ..fmu.info import read_info
from ..spec.model import Spec
from ..stream import WINDOW_ROWS, Grid, percentile_range

__all__ = ["LiveMeasurements", "usable"]


def usable(spec: Spec) -> bool:
    """True where the live run can be windowed: a model-exchange twin and no tag bridging every gap."""
    rule = spec.data.max_gap
    if rule is not None and not math.isfinite(float(rule)):
        return False
    try:
        return "ModelExchange" in read_info(spec.twin).interfaces
    except (TrackingError, OSError):  # the loop words what is wrong with the twin when it loads it
        return False


#: Distinct sampling intervals a tag's count keeps exactly. A historian's irregular timestamps give
#: nearly every interval its own value (the 30-day evaporator: 920,005 distinct, 61 MiB as a Counter
#: of floats); past this many, intervals are counted to 4 significant digits (:class:`_Intervals`)
EXACT_INTERVALS = 20_000


class _Intervals:
    """A tag's sampling intervals, counted for their median in memory that does not grow with the run.

    Exact up to :data:`EXACT_INTERVALS` distinct values (the median is :func:`numpy.median`'s of all
    of them); past that every interval is counted rounded to 4 significant digits (at most 9,000 values
    a decade; the median then within 0.05 % of the exact one).
    """

    def __init__(self) -> None:
        self.counts: Counter[float] = Counter()
        self.coarse = False

    @staticmethod
    def _round(x: float) -> float:
        return float(f"{x:.4g}")

    def add(self, interval: float) -> None:
        if self.coarse:
            self.counts[self._round(interval)] += 1
            return
        self.counts[interval] += 1
        if len(self.counts) > EXACT_INTERVALS:
            merged: Counter[float] = Counter()
            for value, n in self.counts.items():
                merged[self._round(value)] += n
            self.counts, self.coarse = merged, True

    def median(self) -> float:
        return _median(self.counts)

    def __bool__(self) -> bool:
        return bool(self.counts)


def _median(counts: Counter[float]) -> float:
    """The median of the values counted in *counts* (as :func:`numpy.median` of them all)."""
    n = sum(counts.values())
    want, found, seen = [(n - 1) // 2, n // 2], [], 0
    for value in sorted(counts):
        seen += counts[value]
        while want and want[0] < seen:
            found.append(value)
            want.pop(0)
        if not want:
            break
    return 0.5 * (found[0] + found[1])


class _Samples:
    """One tag's samples (s from the origin) and bad-quality events, in time order, droppable from the front."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.v: list[float] = []
        self.start = 0  # entries before this index are dropped (compacted now and then)

    def add(self, t: float, v: float) -> None:
        self.t.append(t)
        self.v.append(v)

    def drop_before(self, t: float) -> None:
        i = int(np.searchsorted(np.asarray(self.t[self.start:]), t, side="left")) + self.start
        self.start = i
        if self.start > 4096 and self.start > len(self.t) // 2:
            del self.t[:self.start], self.v[:self.start]
            self.start = 0

    def between(self, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(self.t[self.start:], dtype=float)
        v = np.asarray(self.v[self.start:], dtype=float)
        i, j = np.searchsorted(t, lo, side="left"), np.searchsorted(t, hi, side="right")
        return t[i:j], v[i:j]

    def __len__(self) -> int:
        return len(self.t) - self.start


class LiveMeasurements:
    """A growing stream of the online mode's samples for a windowed :class:`TrackingLoop` (see the module).

    :meth:`add` takes a sample (``nan``: bad quality), :meth:`grow` sets the rows the loop
    may read (the grid ``k * sample_time`` for ``k < n_rows``), :meth:`view` gives rows
    ``[a, b)``, :meth:`prune` drops what the loop can no longer reach.
    """

    def __init__(self, spec: Spec, source: Path, *, skip: float, rows_per_window: int = WINDOW_ROWS) -> None:
        self.spec = spec
        self.source = Path(source)
        self.ts = float(spec.sample_time)
        self.skip = float(skip)
        self.rows_per_window = int(rows_per_window)
        self.window = (0.0, math.inf)
        self.t0 = 0.0
        self.k_first = 0
        self.n_rows = 0
        self.grid = Grid(self.ts, 0, 0)
        self.max_step = self.ts
        self.tags = view_tags(spec)
        rule = spec.data.max_gap
        self.method: dict[str, str] = {}
        self._fixed: dict[str, float] = {}
        for tag in self.tags:
            hb = spec.data.heartbeat_of(tag)
            self.method[tag] = "linear" if hb is None else "hold"
            if hb is not None:
                self._fixed[tag] = heartbeat_max_gap(hb)
            elif rule is not None:
                self._fixed[tag] = float(rule)
        self._counts: dict[str, _Intervals] = {t: _Intervals() for t in self.tags if t not in self._fixed}
        self._last_valid: dict[str, float] = {}
        self._good = {t: _Samples() for t in self.tags}
        self._bad = {t: _Samples() for t in self.tags}
        stoppage = spec.data.stoppage
        self.settle = float(stoppage.settle) if stoppage is not None else 0.0
        #: rows before a window whose masks reach into it
        self._lead = int(math.ceil((self.settle + 1e-9) / self.ts)) + 1
        #: input tag -> its first valid grid value; grid points where it was missing (rows laid so far)
        self.first_valid: dict[str, float] = {}
        self.input_missing: dict[str, int] = {t: 0 for t in spec.inputs}
        self._counted = 0  # rows counted in input_missing
        #: the inputs' grid values of the rows from _ibuf0 laid so far, and each one's last valid value before
        self._ibuf0 = 0
        self._ibuf: dict[str, np.ndarray] = {}
        self._ibefore: dict[str, float] = {}
        self._ranges: dict[str, tuple[int, float, float]] = {}

    # ------------------------------------------------------------------ samples

    def add(self, tag: str, t: float, value: float) -> None:
        """A sample of *tag* at *t* s from the origin (after the tag's previous one); NaN: bad quality."""
        if tag not in self._good:
            return
        if math.isfinite(value):
            self._good[tag].add(t, value)
            if tag in self._counts:
                last = self._last_valid.get(tag)
                if last is not None:
                    self._counts[tag].add(t - last)
            self._last_valid[tag] = t
        else:
            self._bad[tag].add(t, math.nan)

    @property
    def max_gap(self) -> dict[str, float]:
        """Tag -> its gap limit (s): heartbeat rule, the spec's ``max_gap``, or 2.5 x the median interval so far."""
        out = dict(self._fixed)
        for tag, counts in self._counts.items():
            out[tag] = GAP_FACTOR * counts.median() if counts else math.inf
        return out

    def grow(self, n_rows: int) -> None:
        """The loop may read rows ``0 .. n_rows - 1`` (their samples have come)."""
        self.n_rows = int(n_rows)
        self.grid = Grid(self.ts, 0, self.n_rows)

    def prune(self, k: int) -> None:
        """Drop the samples no window from row ``k - 1`` on can reach."""
        gaps = self.max_gap
        if not all(math.isfinite(g) for g in gaps.values()):
            return
        first = max(0, k - 1 - self._lead)
        if self._ibuf and first > self._ibuf0:
            cut = first - self._ibuf0
            for tag, buf in self._ibuf.items():
                ok = np.flatnonzero(np.isfinite(buf[:cut]))
                if ok.size:
                    self._ibefore[tag] = float(buf[ok[-1]])
                self._ibuf[tag] = buf[cut:]
            self._ibuf0 = first
        for tag in self.tags:
            keep = self.ts * first - gaps[tag] - 2.0 * self.ts
            self._good[tag].drop_before(keep)
            self._bad[tag].drop_before(keep)

    @property
    def held(self) -> int:
        """Samples and events held now (the stream's size)."""
        return sum(len(s) for s in self._good.values()) + sum(len(s) for s in self._bad.values())

    # ------------------------------------------------------------------ windows

    def _samples(self, g: np.ndarray, gaps: dict[str, float], tags: list[str] | None = None) -> dict[str, np.ndarray]:
        out = {}
        for tag in self.tags if tags is None else tags:
            gap = gaps[tag]
            if not math.isfinite(gap):
                raise DataError(f"tag {tag!r} has fewer than two valid samples so far: its gap limit is not known "
                                "(set [data] max_gap to track it live)")
            lo, hi = float(g[0]) - gap - self.ts, float(g[-1]) + gap + self.ts
            t, v = self._good[tag].between(lo, hi)
            bad, _ = self._bad[tag].between(lo, hi)
            column = pd.DataFrame({"time": t, tag: v})
            out[tag] = resample(column, g, max_gap=gap, method=self.method[tag],  # type: ignore[arg-type]
                                breaks={tag: bad})[tag].to_numpy(dtype=float, copy=True)
        return out

    def _before(self, tag: str, a: int) -> float:
        """The input's last valid grid value before row *a* (NaN where there is none: the first valid one is held)."""
        buf = self._ibuf.get(tag)
        if buf is not None and self._ibuf0 <= a <= self._ibuf0 + buf.size:
            y = buf[: a - self._ibuf0]
            ok = np.flatnonzero(np.isfinite(y))
            return float(y[ok[-1]]) if ok.size else self._ibefore[tag]
        if buf is not None and a < self._ibuf0:
            raise DataError(f"the live measurements no longer hold row {a} (they start at row {self._ibuf0}): a "
                            "run that replays its twin from the start needs the whole view (a model-exchange "
                            "twin does not)")
        # nothing laid before this row (a resumed run): the rows before it, back to a valid value
        gaps = self.max_gap
        while a > 0:
            lo = max(0, a - self.rows_per_window)
            y = self._samples(self.ts * np.arange(lo, a, dtype=float), gaps, [tag])[tag]
            ok = np.flatnonzero(np.isfinite(y))
            if ok.size:
                return float(y[ok[-1]])
            a = lo
        return math.nan

    def _keep_inputs(self, a0: int, samples: dict[str, np.ndarray], before: dict[str, float]) -> None:
        """The inputs' grid values of the rows from *a0* (a later window's values replace an earlier one's)."""
        tags = list(self.spec.inputs)
        if not tags:
            return
        end = self._ibuf0 + self._ibuf[tags[0]].size if self._ibuf else -1
        if self._ibuf and self._ibuf0 <= a0 <= end:
            for tag in tags:
                self._ibuf[tag] = np.concatenate([self._ibuf[tag][: a0 - self._ibuf0], samples[tag]])
        else:  # the first rows laid (or a resumed run's): each input's value held before them
            for tag in tags:
                self._ibuf[tag] = samples[tag].copy()
                self._ibefore[tag] = before[tag]
            self._ibuf0 = a0

    def view(self, a: int, b: int) -> MeasurementView:
        """Rows ``[a, b)`` of the grid as the whole view of the samples would have them."""
        if not 0 <= a < b <= self.n_rows:
            raise IndexError(f"rows [{a}, {b}) are not inside the {self.n_rows} rows received")
        a0 = max(0, a - self._lead)
        g = self.ts * np.arange(a0, b, dtype=float)
        spec = self.spec
        before = {tag: self._before(tag, a0) for tag in spec.inputs}
        gaps = self.max_gap
        samples = self._samples(g, gaps)
        if a0 == 0:
            for tag in spec.inputs:
                ok = np.flatnonzero(np.isfinite(samples[tag]))
                if ok.size and tag not in self.first_valid:
                    self.first_valid[tag] = float(samples[tag][ok[0]])
        in_window = np.ones(g.size, dtype=bool)
        stopped, unknown, input_gap, frame, scored, _ = lay_masks(spec, g, samples, in_window, self.skip,
                                                                  {t: v for t, v in before.items() if math.isfinite(v)})
        self._keep_inputs(a0, samples, before)
        if b > self._counted:  # missing input points, each row counted once
            lo = max(self._counted, a0)
            for tag in spec.inputs:
                self.input_missing[tag] += int((~np.isfinite(samples[tag][lo - a0:])).sum())
            self._counted = b
        if not self._ranges:  # the rows the loop starts with give the ranges, as the rebuilt view gave them
            stats = [*(p.variable for p in spec.pairs if p.variable in spec.outputs), *(s.tag for s in spec.states)]
            self._ranges = {tag: percentile_range(samples[tag]) for tag in dict.fromkeys(stats)}
        s = a - a0
        inputs = pd.DataFrame({c: frame[c].to_numpy()[s:] for c in frame.columns})
        return MeasurementView(source=self.source, sample_time=self.ts, window=self.window, grid=g[s:],
                               samples={tag: v[s:] for tag, v in samples.items()}, max_gap=gaps,
                               stopped=stopped[s:], inputs=inputs, scored={t: m[s:] for t, m in scored.items()},
                               skip=self.skip, t0=0.0, method=dict(self.method),  # type: ignore[arg-type]
                               input_gap=input_gap[s:], stoppage_unknown=unknown[s:])

    def inputs_valid(self, rows: int) -> bool:
        """True when every input has a valid value on rows ``[0, rows)`` (the twin can start)."""
        g = self.ts * np.arange(0, rows, dtype=float)
        gaps = self.max_gap
        if not all(math.isfinite(gaps[t]) for t in self.tags):
            return False
        samples = self._samples(g, gaps)
        return all(np.isfinite(samples[t]).any() for t in self.spec.inputs)

    def percentiles(self, tag: str) -> tuple[int, float, float]:
        """``(valid samples, 1st, 99th percentile)`` of *tag* over the rows the loop started with."""
        return self._ranges[tag]

    def close(self) -> None:
        """Nothing to release (the samples are in memory)."""
