"""The measurement view of a long tracking run, window by window (issue 12: memory flat in run length).

:meth:`MeasurementView.from_spec <trackingbox.data.MeasurementView.from_spec>`
holds every tag on the whole grid, and the twins' input tables with it: some
forty floats per sample, and the read's own peak above that. A tracking run
needs only the rows around the one it is at. :class:`WindowedMeasurements`
reads the CSV once, in chunks (:func:`trackingbox.data.clean_chunks`, the
values converted as :func:`~trackingbox.data.read_table` converts them), keeps
the floats of the tags it needs in an unnamed temporary file (row after row,
the same bits) and gives :meth:`~WindowedMeasurements.view` of any stretch of
rows: a :class:`~trackingbox.data.MeasurementView` whose arrays are those of
the whole view over that stretch, bit for bit, because each is made by the
same functions from every raw row that can reach it:

* a tag's samples (:func:`~trackingbox.data.resample`, linear, never across a
  gap longer than its ``max_gap``) from the raw rows within ``max_gap`` plus
  one sample time of the stretch: a grid point's two valid samples are either
  both that close or the point is in a gap (NaN) both ways;
* the tag's ``max_gap`` when the spec sets none (2.5 x its median sampling
  interval, :func:`~trackingbox.data.default_max_gap`) from the exact median
  of all its intervals, counted while reading (regular sampling has a handful
  of distinct intervals);
* the stoppage mask and the input-gap mask (which reach ``settle`` s forward)
  over the stretch and enough rows before it; the twin's inputs held from the
  last valid value before the stretch (:func:`~trackingbox.data.hold_nan`,
  :func:`~trackingbox.data.lay_masks`).

What needs the whole run is computed before it, one tag at a time: the 1st
and 99th percentile of each pair's and each level's samples (the weak-pair
warning, the carry limits, the continuous mode's nominal values), each input's
missing samples and first valid value. The one column held then is 8 bytes a
sample (0.07 MiB a day at 10 s); nothing else grows with the run's length.

Only where this is exact: a wide CSV with seconds in ``time`` that the chunked
reader takes (anything it would report goes to the whole read, which words
it), no ``[data] heartbeat`` tags (sample-and-hold looks at the next archived
value, however far), every tag's ``max_gap`` finite, and at most
:data:`MAX_INTERVALS` distinct sampling intervals per tag. Elsewhere
:meth:`WindowedMeasurements.open` returns ``None`` and the run takes the whole
view (a historian's long export is laid out whole anyway).
"""
from __future__ import annotations

import logging
import math
import tempfile
from collections import Counter
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from .data import (
    GAP_FACTOR,
    LONG_COLUMNS,
    MeasurementView,
    Method,
    WindowArg,
    clean_chunks,
    grid_rows,
    lay_masks,
    resample,
    view_tags,
)
from .data.table import csv_header

if TYPE_CHECKING:
    from .spec import Spec

log = logging.getLogger(__name__)

#: Grid rows per window of a tracking run (plus :data:`MARGIN_ROWS`): 4096 rows are 11 h at 10 s.
WINDOW_ROWS = 4096
#: Rows a window reaches past the last row run in it: the next sample and the solver's look past it.
MARGIN_ROWS = 4
#: Every this many raw rows, the sparse index of the temporary file keeps the row's time.
INDEX_EVERY = 256
#: Most distinct sampling intervals per tag counted for the median (else: the whole view).
MAX_INTERVALS = 4096


class Grid:
    """The grid ``sample_time * k`` for ``k`` in ``[k_first, k_first + size)``, computed where it is read.

    Index ``i`` is ``sample_time * float(k_first + i)``: the same float as the
    whole view's ``sample_time * np.arange(k_first, k_stop, dtype=float)``.
    """

    def __init__(self, sample_time: float, k_first: int, size: int) -> None:
        self.ts = float(sample_time)
        self.k_first = int(k_first)
        self.size = int(size)

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            start, stop, step = i.indices(self.size)
            return self.ts * np.arange(self.k_first + start, self.k_first + stop, step, dtype=float)
        i = int(i)
        if i < 0:
            i += self.size
        if not 0 <= i < self.size:
            raise IndexError(f"grid index {i} out of range (0 .. {self.size - 1})")
        return self.ts * float(self.k_first + i)

    def __array__(self, dtype: Any = None, copy: Any = None) -> npt.NDArray[np.float64]:
        out = self[:]
        return out if dtype is None else out.astype(dtype)


class WindowedMeasurements:
    """A spec's measurements for one run, on the grid of *window*, handed out by stretches of rows.

    Make with :meth:`open`; :meth:`view` gives rows ``[a, b)`` as a
    :class:`~trackingbox.data.MeasurementView` (its ``grid`` those rows'
    times); :attr:`grid` is the whole grid without an array; :meth:`percentiles`,
    :attr:`input_missing` and :attr:`max_step` are what needs every row.
    :meth:`close` drops the temporary file.
    """

    def __init__(self, spec: Spec, *, file: IO[bytes], columns: list[str], index_rows: npt.NDArray[np.int64],
                 index_times: npt.NDArray[np.float64], raw_rows: int, t0: float, window: tuple[float, float],
                 k_first: int, n_rows: int, skip: float, gaps: dict[str, float], rows_per_window: int) -> None:
        self.spec = spec
        self.source = Path(spec.measurements)
        self.ts = float(spec.sample_time)
        self._file = file
        self._columns = columns
        self._col = {c: j for j, c in enumerate(columns)}
        self._index_rows, self._index_times = index_rows, index_times
        self.raw_rows = raw_rows
        self.t0 = t0
        self.window = window
        self.k_first = k_first
        self.n_rows = n_rows
        self.skip = float(skip)
        self.max_gap = gaps
        self.method: dict[str, Method] = {tag: "linear" for tag in gaps}
        self.rows_per_window = int(rows_per_window)
        #: raw data reached around a stretch (s): a grid point's samples are at most max_gap away
        self._reach = max(gaps.values()) + self.ts
        stoppage = spec.data.stoppage
        settle = float(stoppage.settle) if stoppage is not None else 0.0
        #: rows before a stretch whose masks reach into it (the stoppage rule's settle time)
        self._lead = int(math.ceil((settle + 1e-9) / self.ts)) + 1
        self.grid = Grid(self.ts, k_first, n_rows)
        #: input tag -> its first valid sample on the grid (what a hold starts from at the first row)
        self.first_valid: dict[str, float] = {}
        #: input tag -> grid points where it is missing (held for the twin)
        self.input_missing: dict[str, int] = {}
        #: the last stretch laid out: (first row, end row, input tag -> samples, input tag -> value held before)
        self._last: tuple[int, int, dict[str, npt.NDArray[np.float64]], dict[str, float]] | None = None
        self._ranges: dict[str, tuple[int, float, float]] = {}
        #: the smallest interval of the grid (the solver's maximum step, as the whole input table gives it)
        self.max_step = math.inf

    # ------------------------------------------------------------------ building

    @classmethod
    def open(cls, spec: Spec, window: WindowArg = "all", *, skip: float = 0.0, directory: str | Path | None = None,
             stats_tags: Iterable[str] = (), rows_per_window: int = WINDOW_ROWS) -> WindowedMeasurements | None:
        """Read the spec's measurements once into a temporary file in *directory*; None where not exact.

        *stats_tags*: tags whose 1st/99th percentile over the whole grid
        :meth:`percentiles` gives. Errors of the spec's windows are raised as
        :meth:`MeasurementView.from_spec <trackingbox.data.MeasurementView.from_spec>`
        raises them; a file it would report on gives ``None`` (the whole read words it).
        """
        path = Path(spec.measurements)
        needed = view_tags(spec)
        try:
            header = csv_header(path) if path.is_file() else None
        except (OSError, UnicodeDecodeError, ValueError):
            return None
        rule = spec.data.max_gap
        if (header is None or "time" not in header or len(set(header)) != len(header)
                or sorted(header) == list(LONG_COLUMNS) or any(t not in header for t in needed)
                or any(spec.data.heartbeat_of(t) is not None for t in needed)
                or (rule is not None and not math.isfinite(float(rule)))):
            return None
        columns = ["time", *needed]
        file = tempfile.TemporaryFile(dir=directory)
        try:
            made = cls._read(spec, path, header, columns, file, window, skip, rule, rows_per_window)
        except BaseException:
            file.close()
            raise
        if made is None:
            file.close()
            return None
        made._stats(list(dict.fromkeys(stats_tags)))
        return made

    @classmethod
    def _read(cls, spec: Spec, path: Path, header: list[str], columns: list[str], file: IO[bytes],
              window: WindowArg, skip: float, rule: float | None, rows_per_window: int,
              ) -> WindowedMeasurements | None:
        tags = columns[1:]
        rows = 0
        t0 = last_t = math.nan
        any_valid = dict.fromkeys(tags, False)
        last_valid: dict[str, float] = {}
        intervals: dict[str, Counter[float]] = {t: Counter() for t in tags}
        index_rows: list[int] = []
        index_times: list[float] = []
        for chunk in clean_chunks(path, header, allow_nan=True):
            if chunk is None:
                return None
            t = chunk["time"]
            if rows == 0:
                t0 = float(t[0])
            elif not last_t < t[0]:
                return None  # time not increasing across a chunk boundary: the whole read words it
            for j in range(-rows % INDEX_EVERY, t.size, INDEX_EVERY):
                index_rows.append(rows + j)
                index_times.append(float(t[j]))
            np.ascontiguousarray(np.column_stack([chunk[c] for c in columns]), dtype=float).tofile(file)
            for tag in tags:
                y = chunk[tag]
                tv = t[np.isfinite(y)]
                if not tv.size:
                    continue
                any_valid[tag] = True
                if rule is None:
                    counts = intervals[tag]
                    if tag in last_valid:
                        counts[float(tv[0] - last_valid[tag])] += 1
                    counts.update(np.diff(tv).tolist())
                    if len(counts) > MAX_INTERVALS:
                        log.info("tag %r of %s has more than %d distinct sampling intervals: the tracking run "
                                 "reads the measurements whole", tag, path.name, MAX_INTERVALS)
                        return None
                last_valid[tag] = float(tv[-1])
            rows += t.size
            last_t = float(t[-1])
        if rows == 0 or not all(any_valid.values()):
            return None  # no rows, or a tag with no value at all: the whole read words it
        gaps: dict[str, float] = {}
        for tag in tags:
            if rule is not None:
                gaps[tag] = float(rule)
                continue
            counts = intervals[tag]
            n = sum(counts.values())
            if n < 1:
                return None  # fewer than two valid samples: any gap is bridged, no window is exact
            gaps[tag] = GAP_FACTOR * _median(counts, n)
        file.flush()
        end = last_t - t0
        start, stop, k_first, k_stop = grid_rows(spec, window, end, None)
        made = cls(spec, file=file, columns=columns, index_rows=np.asarray(index_rows, dtype=np.int64),
                   index_times=np.asarray(index_times, dtype=float), raw_rows=rows, t0=t0, window=(start, stop),
                   k_first=k_first, n_rows=k_stop - k_first, skip=skip, gaps=gaps, rows_per_window=rows_per_window)
        log.debug("measurements of %s for a windowed run: %d rows in a temporary file, %d grid points, gap limits %s",
                  path.name, rows, made.n_rows, gaps)
        return made

    def _stats(self, stats_tags: Sequence[str]) -> None:
        """What needs every row, one tag at a time: inputs' first values and gaps, percentiles, the grid's step."""
        step = self.rows_per_window
        for r in range(0, self.n_rows, step):
            g = self.grid[r: min(self.n_rows, r + step + 1)]
            if g.size > 1:
                self.max_step = min(self.max_step, float(np.min(np.diff(g))))
        for tag in self.spec.inputs:
            missing, first = 0, math.nan
            for r in range(0, self.n_rows, step):
                y = self._samples(tag, r, min(self.n_rows, r + step))
                ok = np.isfinite(y)
                missing += int(y.size - np.count_nonzero(ok))
                if math.isnan(first) and ok.any():
                    first = float(y[np.flatnonzero(ok)[0]])
            self.input_missing[tag] = missing
            self.first_valid[tag] = first
        for tag in stats_tags:
            column = np.concatenate([self._samples(tag, r, min(self.n_rows, r + step))
                                     for r in range(0, self.n_rows, step)])
            self._ranges[tag] = percentile_range(column)

    # ------------------------------------------------------------------ reading

    def _raw(self, lo: float, hi: float) -> npt.NDArray[np.float64]:
        """Raw rows (``columns``) from at least every row with ``lo <= time - t0 <= hi``: a contiguous run of rows."""
        times = self._index_times - self.t0
        i = int(np.searchsorted(times, lo, side="right")) - 1
        j = int(np.searchsorted(times, hi, side="right"))
        first = int(self._index_rows[max(i, 0)])
        last = int(self._index_rows[j]) if j < self._index_rows.size else self.raw_rows
        n = len(self._columns)
        self._file.seek(first * n * 8)
        data = np.fromfile(self._file, dtype=float, count=(last - first) * n)
        return data.reshape(-1, n)

    def _grid(self, a: int, b: int) -> npt.NDArray[np.float64]:
        return self.ts * np.arange(self.k_first + a, self.k_first + b, dtype=float)

    def _samples(self, tag: str, a: int, b: int, raw: npt.NDArray[np.float64] | None = None,
                 grid: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.float64]:
        """Tag *tag* on rows ``[a, b)`` of the grid, as the whole view has it."""
        g = self._grid(a, b) if grid is None else grid
        if raw is None:
            raw = self._raw(float(g[0]) - self._reach, float(g[-1]) + self._reach)
        column = pd.DataFrame({"time": raw[:, 0], tag: raw[:, self._col[tag]]})
        gap = self.max_gap[tag]
        return resample(column, self.t0 + g, max_gap=gap, method="linear", breaks={tag: ()})[tag] \
            .to_numpy(dtype=float, copy=True)

    def _before(self, tag: str, a: int) -> float:
        """The input *tag*'s last valid sample before row *a* (its first valid one if there is none)."""
        last = self._last
        while a > 0:
            if last is not None and last[0] <= a <= last[1]:
                y = last[2][tag][: a - last[0]]
                ok = np.flatnonzero(np.isfinite(y))
                return float(y[ok[-1]]) if ok.size else last[3][tag]
            lo = max(0, a - self.rows_per_window)
            y = self._samples(tag, lo, a)
            ok = np.flatnonzero(np.isfinite(y))
            if ok.size:
                return float(y[ok[-1]])
            a, last = lo, None
        return self.first_valid[tag]

    def view(self, a: int, b: int) -> MeasurementView:
        """Rows ``[a, b)`` of the grid as a :class:`~trackingbox.data.MeasurementView` (the whole view's slice)."""
        if not 0 <= a < b <= self.n_rows:
            raise IndexError(f"rows [{a}, {b}) are not inside the grid's {self.n_rows}")
        a0 = max(0, a - self._lead)
        g = self._grid(a0, b)
        raw = self._raw(float(g[0]) - self._reach, float(g[-1]) + self._reach)
        spec = self.spec
        samples = {tag: self._samples(tag, a0, b, raw, g) for tag in self._columns[1:]}
        before = {tag: self._before(tag, a0) for tag in spec.inputs}
        start, stop = self.window
        in_window = (g >= start - 1e-9) & (g < stop - 1e-9)
        stopped, unknown, input_gap, frame, scored, _ = lay_masks(spec, g, samples, in_window, self.skip, before)
        self._last = (a0, b, {tag: samples[tag] for tag in spec.inputs}, before)
        s = a - a0
        inputs = pd.DataFrame({c: frame[c].to_numpy()[s:] for c in frame.columns})
        return MeasurementView(source=self.source, sample_time=self.ts, window=self.window, grid=g[s:],
                               samples={tag: v[s:] for tag, v in samples.items()}, max_gap=dict(self.max_gap),
                               stopped=stopped[s:], inputs=inputs, scored={t: m[s:] for t, m in scored.items()},
                               skip=self.skip, t0=self.t0, method=dict(self.method), input_gap=input_gap[s:],
                               stoppage_unknown=unknown[s:])

    def percentiles(self, tag: str) -> tuple[int, float, float]:
        """``(valid samples, 1st percentile, 99th percentile)`` of *tag* over the whole grid (a *stats_tags* tag)."""
        return self._ranges[tag]

    def close(self) -> None:
        """Drop the temporary file."""
        self._file.close()


def percentile_range(values: npt.ArrayLike) -> tuple[int, float, float]:
    """``(n, p1, p99)``: the number of finite values and their 1st and 99th percentiles (NaN below 2 values).

    >>> percentile_range([np.nan, 0.0, 1.0])
    (2, 0.01, 0.99)
    """
    v = np.asarray(values, dtype=float)
    ok = v[np.isfinite(v)]
    if ok.size < 2:
        return int(ok.size), math.nan, math.nan
    lo, hi = np.percentile(ok, [1.0, 99.0])
    return int(ok.size), float(lo), float(hi)


def _median(counts: Counter[float], n: int) -> float:
    """The median of *n* values given as value -> count, as :func:`numpy.median` computes it."""
    want = [(n - 1) // 2, n // 2]
    found: list[float] = []
    seen = 0
    for value in sorted(counts):
        seen += counts[value]
        while want and want[0] < seen:
            found.append(value)
            want.pop(0)
        if not want:
            break
    return float(np.mean(np.asarray(found if n % 2 == 0 else found[:1], dtype=float)))
