"""Measurement and input tables: reading, validation, resampling, NaN spans, the measurement view.

A table is a CSV file with a ``time`` column and one numeric column per tag or
FMU input. ``time`` is either seconds (floats) or ISO 8601 timestamps; timestamps
are converted to seconds from the first row and the first timestamp is kept in
``df.attrs["t0"]``. A plant historian's *long* export (``tag,time,value``, one
row per archived value, :mod:`trackingbox.benches.historian`) is read too: it is
laid out wide (one row per time at which any tag was archived, NaN where a tag
was not), and its bad-quality events (empty ``value``) are kept per tag in
``df.attrs["breaks"]``: a tag's value is unknown from such an event until its
next record, and nothing is interpolated across it.

:func:`read_table` checks everything it can and reports *all* problems of a file
in one :class:`~trackingbox.errors.DataError`, so a user fixes a file in one go.

:class:`MeasurementView` is what every stage (estimation, pairing, tracking,
validation, the offset analysis) uses: the spec's measurements read once,
resampled onto the simulation grid with one gap rule, the stoppage mask, the
twin's input table and the samples each tag is scored on. No stage reads or
resamples the CSV itself.
"""
from __future__ import annotations

import csv
import logging
import math
import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Union

import numpy as np
import numpy.typing as npt
import pandas as pd

from .errors import DataError, SpecError, did_you_mean

if TYPE_CHECKING:
    from .spec import Spec

log = logging.getLogger(__name__)

#: Cells that mean "no value" (read as NaN, not as a non-numeric cell).
NA_VALUES = ("", "NaN", "nan", "NAN", "NA", "N/A", "n/a", "null", "NULL", "None", "#N/A")

_MAX_LISTED = 3  # cells listed per column in a message


def _fmt(t: float) -> str:
    return f"{t:g} s"


def _n(count: int, noun: str) -> str:
    """``"1 NaN value"``, ``"412 NaN values"``."""
    return f"{count} {noun}" if count == 1 else f"{count} {noun}s"


def _line(i: int) -> int:
    """CSV line number of data row *i* (0-based; line 1 is the header)."""
    return i + 2


def _parse_time(raw: pd.Series, where: str, problems: list[str]) -> tuple[npt.NDArray[np.float64], object]:
    """Seconds for the time column and the first timestamp (or ``None``)."""
    missing = raw.isna().to_numpy()
    numeric = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float)
    non_numeric = ~missing & np.isnan(numeric)
    t0: object = None
    if non_numeric.any():
        present = raw[~missing]
        parsed = None
        for kwargs in ({}, {"utc": True}):
            try:
                parsed = pd.to_datetime(present, format="ISO8601", **kwargs)
                break
            except (ValueError, TypeError):
                continue
        if parsed is None:
            # say which cells are neither numbers nor timestamps
            bad = []
            for i, text in raw.items():
                if missing[i] or not np.isnan(numeric[i]):
                    continue
                try:
                    pd.Timestamp(text)
                except (ValueError, TypeError):
                    bad.append(f"{_cell(text)} on line {_line(int(i))}")
            listed = ", ".join(bad[:_MAX_LISTED]) + (f" (and {len(bad) - _MAX_LISTED} more)"
                                                     if len(bad) > _MAX_LISTED else "")
            problems.append(f"column 'time' in {where} has values that are neither seconds nor ISO 8601 "
                            f"timestamps: {listed or 'mixed numbers and timestamps'}")
            return numeric, None
        seconds = np.full(len(raw), np.nan)
        t0 = parsed.iloc[0]
        seconds[~missing] = (parsed - t0).dt.total_seconds().to_numpy(dtype=float)
        numeric = seconds
    if missing.any():
        rows = np.flatnonzero(missing)
        problems.append(f"column 'time' in {where} has {_n(rows.size, 'empty value')}, first on line {_line(int(rows[0]))}")
    return numeric, t0


def _check_time_order(t: npt.NDArray[np.float64], where: str, problems: list[str]) -> None:
    inf = np.flatnonzero(np.isinf(t))
    if inf.size:
        problems.append(f"column 'time' in {where} has {_n(inf.size, 'infinite value')}, first on line "
                        f"{_line(int(inf[0]))}")
        t = np.where(np.isinf(t), np.nan, t)
    valid = np.flatnonzero(~np.isnan(t))
    if valid.size < 2:
        return
    tv = t[valid]
    with np.errstate(over="ignore"):  # times near the float limits: their difference is +-inf, its sign right
        d = np.diff(tv)
    dup = np.flatnonzero(d == 0)
    back = np.flatnonzero(d < 0)
    if dup.size:
        i = int(valid[dup[0] + 1])
        problems.append(f"column 'time' in {where} has duplicate times: line {_line(i)} repeats {_fmt(t[i])} "
                        f"({_n(dup.size, 'duplicate')} in all)")
    if back.size:
        i = int(valid[back[0] + 1])
        j = int(valid[back[0]])
        problems.append(f"column 'time' in {where} goes backwards: line {_line(i)} has {_fmt(t[i])} after "
                        f"{_fmt(t[j])} on line {_line(j)} ({_n(back.size, 'decrease')} in all)")


def _numeric(col: pd.Series, what: str, problems: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The empty cells and the float values of one column; non-numeric and infinite
    values are added to *problems* with their lines (*what* names the column and file)."""
    na = col.isna().to_numpy()
    values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=float)
    bad = np.flatnonzero(~na & np.isnan(values))
    if bad.size:
        cells = ", ".join(f"{_cell(col.iloc[i])} on line {_line(int(i))}" for i in bad[:_MAX_LISTED])
        more = f" (and {bad.size - _MAX_LISTED} more)" if bad.size > _MAX_LISTED else ""
        problems.append(f"{what} has non-numeric values: {cells}{more}")
    infinite = np.flatnonzero(np.isinf(values))
    if infinite.size:
        problems.append(f"{what} has infinite values, first on line {_line(int(infinite[0]))}")
    huge = np.flatnonzero(np.isfinite(values) & (np.abs(values) > MAX_MAGNITUDE))
    if huge.size:
        i = int(huge[0])
        problems.append(f"{what} has values beyond +-{MAX_MAGNITUDE:g} (their squares overflow), first "
                        f"{values[i]:g} on line {_line(i)}")
    return na, values


#: largest magnitude of a value in a table: sums of squares of such values stay finite
MAX_MAGNITUDE = 1e150
#: longest cell text quoted in a message
_MAX_CELL = 40
#: most grid points a measurement view may have (its memory is a few arrays of this length per tag)
MAX_GRID_POINTS = 20_000_000


def _cell(text: object) -> str:
    """*text* quoted for a message, shortened to :data:`_MAX_CELL` characters."""
    shown = repr(text)
    return shown if len(shown) <= _MAX_CELL else f"{shown[:_MAX_CELL - 10]}...' ({len(str(text))} characters)"


def _header(path: Path) -> list[str] | None:
    with path.open(newline="", encoding="utf-8") as fh:
        for row in csv.reader(fh):
            return [c.strip() for c in row]
    return None


#: Rows converted at a time by :func:`_read_clean`: its text cells never exceed this many rows.
CHUNK_ROWS = 2048


def _read_clean(path: Path, header: list[str], *, required: Iterable[str], allow_nan: bool) -> pd.DataFrame | None:
    """A wide table with seconds in ``time`` and nothing to report, read in chunks of :data:`CHUNK_ROWS` rows.

    Why: the cells are text until converted, and a text cell costs about 60
    bytes where its float costs 8; reading the whole file as text first made
    the memory a run needs grow with its length (a 7-day heat-exchanger file
    took some 40 MiB more at its peak than a 1-day one). Each chunk is read as
    text and converted exactly as :func:`read_table` converts (``pd.to_numeric``,
    the same :data:`NA_VALUES`), so the values are the same bits; only the
    floats are kept. Returns ``None`` -- the caller then reads the file whole,
    which finds and words every problem -- as soon as anything would be a
    problem or is not plain: no ``time`` column, duplicate or missing columns,
    the long form, no rows, a time that is not a number of seconds, missing or
    not increasing, a cell that is not a number, an infinite or too large value,
    or an empty cell where none is allowed.
    """
    columns = list(header)
    if ("time" not in columns or len(set(columns)) != len(columns) or sorted(columns) == list(LONG_COLUMNS)
            or any(c not in columns for c in required)):
        return None
    parts: dict[str, list[np.ndarray]] = {c: [] for c in columns}
    for converted in clean_chunks(path, columns, allow_nan=allow_nan):
        if converted is None:
            return None
        for name, values in converted.items():
            parts[name].append(values)
    if not parts["time"]:
        return None
    ends = [(p[0], p[-1]) for p in parts["time"]]
    if any(prev[1] >= nxt[0] for prev, nxt in zip(ends, ends[1:])):
        return None  # time not increasing across a chunk boundary
    order = ["time", *(c for c in columns if c != "time")]
    # column by column, each chunk list dropped once joined; not consolidated (no second copy)
    out = pd.DataFrame({c: np.concatenate(parts.pop(c)) for c in order}, copy=False)
    out.attrs["t0"] = None
    out.attrs["source"] = str(path)
    return out


def clean_chunks(path: Path, columns: list[str], *, allow_nan: bool,
                 chunk_rows: int | None = None) -> Iterator[dict[str, np.ndarray] | None]:
    """The chunks of :func:`_read_clean` one by one: column -> floats, ``None`` once anything would be a problem.

    For a reader that keeps only what it needs of each chunk (the windowed
    measurements of a long tracking run, :mod:`trackingbox.stream`); *columns*
    is the file's header. A ``None`` ends the iteration: :func:`read_table`
    then words the problem. Time increasing across chunk boundaries is the
    caller's to check.
    """
    try:
        with pd.read_csv(path, dtype=str, na_values=list(NA_VALUES), keep_default_na=False,
                         skipinitialspace=True, chunksize=chunk_rows or CHUNK_ROWS) as reader:
            for chunk in reader:
                converted = _clean_chunk(chunk, columns, allow_nan)
                yield converted
                if converted is None:
                    return
    except ValueError:  # not parseable as CSV, not UTF-8: the whole-file read words it
        yield None


def _clean_chunk(chunk: pd.DataFrame, columns: list[str], allow_nan: bool) -> dict[str, np.ndarray] | None:
    """Convert one chunk of :func:`_read_clean`; None if it holds anything to report."""
    if len(chunk) == 0 or [str(c).strip() for c in chunk.columns] != columns:
        return None
    converted = {}
    for c, name in zip(chunk.columns, columns):
        cells = chunk[c]
        na = cells.isna().to_numpy()
        values = pd.to_numeric(cells, errors="coerce").to_numpy(dtype=float)
        finite = np.isfinite(values)
        if name == "time":
            if na.any() or not finite.all():
                return None
            with np.errstate(over="ignore"):  # times near the float limits: their difference is +-inf
                if np.any(np.diff(values) <= 0):
                    return None
        elif (not finite[~na].all() or np.any(np.abs(values[finite]) > MAX_MAGNITUDE)
              or (not allow_nan and na.any())):
            return None  # a non-numeric, infinite or huge cell, or an empty one where none may be
        converted[name] = values
    return converted


def read_table(
    path: str | os.PathLike[str],
    *,
    required: Iterable[str] = (),
    allow_nan: bool = False,
    what: str = "measurements",
) -> pd.DataFrame:
    """Read and validate a CSV table with a ``time`` column.

    Parameters
    ----------
    path
        The CSV file.
    required
        Columns that must be present (besides ``time``).
    allow_nan
        Whether empty/NaN cells are allowed in the data columns.
    what
        What the file is, for messages ("measurements", "inputs").

    Returns
    -------
    pandas.DataFrame
        ``time`` (float seconds, from the first row for ISO 8601 timestamps) and
        every other column as float. ``df.attrs["t0"]`` is the first timestamp
        (a :class:`pandas.Timestamp`) when time was given as timestamps, else
        ``None``; ``df.attrs["source"]`` is the path.

    Raises
    ------
    DataError
        With every problem found: missing/unreadable/non-CSV file, no ``time``
        column, missing required columns, duplicate column names, non-numeric
        cells, duplicate or decreasing time, NaN values (unless allowed).
    """
    path = Path(path)
    where = path.name
    if not path.exists():
        raise DataError(f"{what} file {path} does not exist")
    if path.is_dir():
        raise DataError(f"{what} file {path} is a directory, not a CSV file")
    try:
        header = _header(path)
        if header is not None:
            clean = _read_clean(path, header, required=required, allow_nan=allow_nan)
            if clean is not None:
                log.debug("read %s: %d rows, columns %s", path, len(clean), list(clean.columns))
                return clean
        raw = pd.read_csv(path, dtype=str, na_values=list(NA_VALUES), keep_default_na=False,
                          skipinitialspace=True)
    except UnicodeDecodeError:
        raise DataError(f"{what} file {path} is not a CSV text file (it is not UTF-8 text)") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, csv.Error) as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else "no data"
        raise DataError(f"{what} file {path} cannot be read as CSV: {msg}") from None
    except OSError as exc:
        raise DataError(f"{what} file {path} cannot be read: {exc.strerror or exc}") from None
    if header is None:
        raise DataError(f"{what} file {path} is empty")
    raw.columns = [str(c).strip() for c in raw.columns]
    if sorted(header) == list(LONG_COLUMNS):
        return _read_long(raw, path, required=required, allow_nan=allow_nan, what=what)

    problems: list[str] = []
    kind = "tag" if what == "measurements" else "column"
    dups = sorted({c for c in header if header.count(c) > 1})
    if dups:
        problems.append(f"{where} has duplicate column names: {', '.join(map(repr, dups))}")
        raw.columns = header if len(header) == len(raw.columns) else raw.columns
        raw = raw.loc[:, ~raw.columns.duplicated()]
    columns = list(raw.columns)
    has_time = "time" in columns
    if not has_time:
        hint = ""
        if len(columns) == 1 and any(sep in columns[0] for sep in (";", "\t")):
            hint = "; the file does not look comma-separated (columns must be separated by ',')"
        problems.append(f"{where} has no 'time' column{did_you_mean('time', columns)} "
                        f"(columns: {', '.join(map(repr, columns)) or 'none'}){hint}")
    missing = [c for c in required if c not in columns]
    for c in missing:
        problems.append(f"{kind} {c!r} is missing from {where}{did_you_mean(c, columns)}")
    if len(raw) == 0:
        problems.append(f"{where} has a header but no data rows")

    out = pd.DataFrame(index=raw.index)
    t: npt.NDArray[np.float64] | None = None
    t0: object = None
    if has_time and len(raw):
        t, t0 = _parse_time(raw["time"], where, problems)
        _check_time_order(t, where, problems)
        out["time"] = t
    for c in columns:
        if c == "time":
            continue
        col = raw[c]
        na, values = _numeric(col, f"{kind} {c!r} in {where}", problems)
        if not allow_nan and na.any():
            rows = np.flatnonzero(na)
            if t is not None and not np.all(np.isnan(t[rows])):
                lo, hi = np.nanmin(t[rows]), np.nanmax(t[rows])
                span = f" at {_fmt(lo)}" if lo == hi else f" between {_fmt(lo)} and {_fmt(hi)}"
            else:
                span = f" between lines {_line(int(rows[0]))} and {_line(int(rows[-1]))}"
            problems.append(f"{kind} {c!r} in {where} has {_n(rows.size, 'NaN value')}{span}")
        out[c] = values

    if problems:
        if len(problems) == 1:
            raise DataError(problems[0])
        raise DataError(f"{what} file {where} has {len(problems)} problems:\n  - " + "\n  - ".join(problems))
    out = out.reset_index(drop=True)
    out.attrs["t0"] = t0
    out.attrs["source"] = str(path)
    log.debug("read %s: %d rows, columns %s", path, len(out), list(out.columns))
    return out


#: Columns of a historian's long export (any order).
LONG_COLUMNS = ("tag", "time", "value")


def _read_long(raw: pd.DataFrame, path: Path, *, required: Iterable[str], allow_nan: bool,
               what: str) -> pd.DataFrame:
    """The long form (``tag,time,value``) laid out wide, bad-quality events in ``attrs["breaks"]``."""
    where = path.name
    problems: list[str] = []
    kind = "tag" if what == "measurements" else "column"
    if len(raw) == 0:
        raise DataError(f"{where} has a header but no data rows")
    tags = raw["tag"].fillna("").astype(str).str.strip()
    empty_tag = np.flatnonzero(tags.to_numpy() == "")
    if empty_tag.size:
        problems.append(f"column 'tag' in {where} has {_n(empty_tag.size, 'empty value')}, "
                        f"first on line {_line(int(empty_tag[0]))}")
    t, t0 = _parse_time(raw["time"], where, problems)
    na, values = _numeric(raw["value"], f"column 'value' in {where}", problems)
    names = list(dict.fromkeys(tags[tags != ""]))
    for c in required:
        if c not in names:
            problems.append(f"{kind} {c!r} is missing from {where}{did_you_mean(c, names)}")
    if t0 is not None:
        # seconds from the earliest timestamp, not from the first row (the file is sorted by tag)
        first = np.nanmin(t)
        t0 = t0 + pd.Timedelta(seconds=float(first))
        t = t - first
    for name in names:
        rows = np.flatnonzero((tags == name).to_numpy())
        tt = t[rows]
        ok = rows[np.isfinite(tt)]
        d = np.diff(t[ok])
        if np.any(d == 0):
            i = int(ok[np.flatnonzero(d == 0)[0] + 1])
            problems.append(f"tag {name!r} in {where} has duplicate times: line {_line(i)} repeats {_fmt(t[i])}")
        if np.any(d < 0):
            k = int(np.flatnonzero(d < 0)[0])
            problems.append(f"tag {name!r} in {where} goes backwards: line {_line(int(ok[k + 1]))} has "
                            f"{_fmt(t[ok[k + 1]])} after {_fmt(t[ok[k]])} on line {_line(int(ok[k]))}")
        if not allow_nan and na[rows].any():
            first_na = int(rows[np.flatnonzero(na[rows])[0]])
            problems.append(f"{kind} {name!r} in {where} has {_n(int(na[rows].sum()), 'bad-quality value')} "
                            f"(empty 'value'), first on line {_line(first_na)}")
    if problems:
        if len(problems) == 1:
            raise DataError(problems[0])
        raise DataError(f"{what} file {where} has {len(problems)} problems:\n  - " + "\n  - ".join(problems))
    records = pd.DataFrame({"tag": tags.to_numpy(), "time": t, "value": values})
    table = records.pivot(index="time", columns="tag", values="value").reindex(columns=names).sort_index()
    out = pd.DataFrame({"time": table.index.to_numpy(dtype=float)})
    for name in names:
        out[name] = table[name].to_numpy(dtype=float)
    bad_events = records[np.isnan(records["value"].to_numpy())]
    out.attrs["t0"] = t0
    out.attrs["source"] = str(path)
    # tuples, not arrays: pandas compares attrs when it combines frames
    out.attrs["breaks"] = {str(name): tuple(sorted(float(x) for x in g["time"]))
                           for name, g in bad_events.groupby("tag", sort=False)}
    log.debug("read %s (long form): %d records, %d tags, %d bad-quality events", path, len(records), len(names),
              len(bad_events))
    return out


Method = Literal["linear", "hold"]


def resample(df: pd.DataFrame, grid: Sequence[float] | npt.ArrayLike, max_gap: float | None = None, *,
             method: Method = "linear", breaks: Mapping[str, npt.ArrayLike] | None = None) -> pd.DataFrame:
    """Interpolate every column of *df* onto the time *grid*, never across long gaps.

    Method: for each column separately, take only that column's valid (non-NaN)
    samples and interpolate linearly between the two valid samples around each
    grid point. A grid point becomes NaN when

    * it lies before the column's first or after its last valid sample (no
      extrapolation), or
    * the two valid samples around it are more than *max_gap* seconds apart
      (the point is inside a gap; grid points that coincide with a valid sample
      keep that sample's value), or
    * a bad-quality event of the column (*breaks*) lies between the point's two
      valid samples (communication loss: the value is not known there).

    With ``method="hold"`` (exception-reported tags) a grid point takes the
    value of the column's last valid sample at or before it (sample-and-hold),
    also after the last sample for up to *max_gap*; it is NaN before the first
    sample, when the samples around it are more than *max_gap* apart, and from a
    bad-quality event to the next valid sample.

    Parameters
    ----------
    df
        Table with a ``time`` column (s), strictly increasing.
    grid
        Target times (s), increasing.
    max_gap
        Longest span (s) between valid samples that may be bridged; ``None``:
        any gap is bridged.
    method
        ``"linear"`` interpolation or ``"hold"`` (sample-and-hold).
    breaks
        Column -> times (s) of bad-quality events (``df.attrs["breaks"]`` of a
        historian's long export when not given).

    Returns
    -------
    pandas.DataFrame
        ``time`` = *grid* and the other columns of *df*, resampled.

    Examples
    --------
    >>> df = pd.DataFrame({"time": [0.0, 10.0, 20.0, 100.0], "T": [0.0, 1.0, 2.0, 10.0]})
    >>> resample(df, [5.0, 15.0, 50.0], max_gap=30.0)["T"].tolist()
    [0.5, 1.5, nan]
    >>> resample(df, [5.0, 15.0, 50.0], max_gap=30.0, method="hold")["T"].tolist()
    [0.0, 1.0, nan]
    >>> resample(df, [5.0, 15.0], breaks={"T": [12.0]}, method="hold")["T"].tolist()
    [0.0, nan]
    """
    if "time" not in df.columns:
        raise DataError("cannot resample a table without a 'time' column")
    if method not in ("linear", "hold"):
        raise DataError(f"resample method must be 'linear' or 'hold', not {method!r}")
    if breaks is None:
        breaks = df.attrs.get("breaks") or {}
    g = np.asarray(grid, dtype=float).ravel()
    t = df["time"].to_numpy(dtype=float)
    out = {"time": g}
    for c in df.columns:
        if c == "time":
            continue
        y = df[c].to_numpy(dtype=float)
        ok = ~np.isnan(y) & ~np.isnan(t)
        tv, yv = t[ok], y[ok]
        res = np.full(g.shape, np.nan)
        b = np.sort(np.asarray(breaks.get(c, ()), dtype=float))
        if method == "hold":
            res = _hold(g, tv, yv, max_gap, b)
        elif tv.size == 1:
            res[g == tv[0]] = yv[0]
        elif tv.size > 1:
            inside = (g >= tv[0]) & (g <= tv[-1])
            res[inside] = np.interp(g[inside], tv, yv)
            if max_gap is not None:
                i = np.clip(np.searchsorted(tv, g, side="right"), 1, tv.size - 1)
                left, right = tv[i - 1], tv[i]
                exact = np.isin(g, tv)
                in_gap = inside & ((right - left) > max_gap) & ~exact
                res[in_gap] = np.nan
        if method == "linear" and b.size and tv.size:
            res[_across_break(g, tv, b)] = np.nan
        out[c] = res
    result = pd.DataFrame(out)
    result.attrs.update(df.attrs)
    return result


def _hold(g: npt.NDArray[np.float64], tv: npt.NDArray[np.float64], yv: npt.NDArray[np.float64],
          max_gap: float | None, b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Sample-and-hold of the valid samples ``(tv, yv)`` on *g*.

    A point holds its last sample (``left``) unless a bad-quality event (times
    *b*) came after that sample, or the silence it sits in is longer than
    *max_gap*: the silence runs from ``left`` to the next sample, or to the
    next bad event if that comes first (the loss began there), or, after the
    last sample, to the point itself.
    """
    res = np.full(g.shape, np.nan)
    if tv.size == 0:
        return res
    i = np.searchsorted(tv, g, side="right") - 1
    have = i >= 0
    left = np.where(have, tv[np.clip(i, 0, None)], -np.inf)
    res[have] = yv[i[have]]
    exact = have & (left == g)
    right = np.where(i + 1 < tv.size, tv[np.clip(i + 1, 0, tv.size - 1)], g)
    if b.size:
        k = np.searchsorted(b, left, side="right")  # first bad event after the last sample
        next_break = np.where(k < b.size, b[np.clip(k, 0, b.size - 1)], np.inf)
        res[have & ~exact & (next_break <= g)] = np.nan  # inside the loss
        right = np.minimum(right, next_break)
    if max_gap is not None:
        res[have & ~exact & ((right - left) > max_gap)] = np.nan
    return res


def _across_break(g: npt.NDArray[np.float64], tv: npt.NDArray[np.float64],
                  b: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """Grid points whose two valid samples around them have a bad-quality event (times *b*) between them."""
    i = np.searchsorted(tv, g, side="right") - 1
    left = np.where(i >= 0, tv[np.clip(i, 0, None)], -np.inf)
    right = np.where(i + 1 < tv.size, tv[np.clip(i + 1, 0, tv.size - 1)], np.inf)
    exact = (i >= 0) & (left == g)
    k = np.searchsorted(b, left, side="right")
    next_break = np.where(k < b.size, b[np.clip(k, 0, b.size - 1)], np.inf)
    return (next_break < right) & ~exact


def window(df: pd.DataFrame, start: float, stop: float) -> pd.DataFrame:
    """Rows with ``start <= time < stop`` (a half-open window, as in spec.toml), index reset.

    >>> df = pd.DataFrame({"time": [0.0, 10.0, 20.0], "T": [1.0, 2.0, 3.0]})
    >>> window(df, 0.0, 20.0)["time"].tolist()
    [0.0, 10.0]
    """
    if "time" not in df.columns:
        raise DataError("cannot take a time window of a table without a 'time' column")
    if stop < start:
        raise DataError(f"time window [{start:g}, {stop:g}) ends before it starts")
    t = df["time"].to_numpy(dtype=float)
    out = df.loc[(t >= start) & (t < stop)].reset_index(drop=True)
    out.attrs.update(df.attrs)
    return out


def nan_spans(series: pd.Series, time: npt.ArrayLike | None = None) -> list[tuple[float, float]]:
    """Runs of consecutive NaN values as ``(t_start, t_end)``: times of the first and last NaN of each run.

    Parameters
    ----------
    series
        Values, in time order.
    time
        Time of each value; default: the series' index.

    >>> s = pd.Series([1.0, np.nan, np.nan, 4.0, np.nan], index=[0.0, 10.0, 20.0, 30.0, 40.0])
    >>> nan_spans(s)
    [(10.0, 20.0), (40.0, 40.0)]
    """
    values = np.asarray(series, dtype=float)
    t = np.asarray(series.index if time is None else time, dtype=float)
    if t.shape != values.shape:
        raise DataError(f"nan_spans: {values.size} values but {t.size} times")
    na = np.isnan(values)
    if not na.any():
        return []
    edges = np.diff(np.concatenate(([0], na.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends)]


def stoppage_mask(grid: np.ndarray, values: np.ndarray, below: float, settle: float = 0.0) -> np.ndarray:
    """True on the grid inside a stoppage and for *settle* seconds after it.

    A stoppage is where the tag's value is below *below* (the spec's
    ``data.stoppage`` rule). Samples there, and up to *settle* s after the last
    stopped sample, are excluded from costs and hold the parameter
    controllers. NaN values are not a stoppage (they are missing data).

    >>> stoppage_mask(np.array([0., 10., 20., 30., 40.]), np.array([1., 0., 1., 1., 1.]), 0.5, 10.0).tolist()
    [False, True, True, False, False]
    """
    grid = np.asarray(grid, dtype=float)
    values = np.asarray(values, dtype=float)
    stopped = np.isfinite(values) & (values < below)
    if not stopped.any():
        return stopped
    stop_times = grid[stopped]
    idx = np.searchsorted(stop_times, grid, side="right") - 1
    last = np.where(idx >= 0, stop_times[np.clip(idx, 0, None)], -np.inf)
    return (grid - last) <= settle + 1e-9


def fill_nan(values: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Linear interpolation over NaN between valid samples, held at both ends.

    For signals that must be finite everywhere (the twin's inputs, the tracked
    FMU's measurement inputs). All-NaN or all-valid input is returned as is.

    >>> fill_nan([np.nan, 1.0, np.nan, 3.0, np.nan]).tolist()
    [1.0, 1.0, 2.0, 3.0, 3.0]
    """
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v)
    if ok.all() or not ok.any():
        return v
    idx = np.arange(v.size)
    return np.interp(idx, idx[ok], v[ok])


def hold_nan(values: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The last valid value held over NaN (sample-and-hold), the first valid value before it.

    What a process modeller gives a twin's input through a historian gap: the
    last good value, never a line drawn towards a value that was not known yet.
    All-NaN or all-valid input is returned as is.

    >>> hold_nan([np.nan, 1.0, np.nan, 3.0, np.nan]).tolist()
    [1.0, 1.0, 1.0, 3.0, 3.0]
    """
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v)
    if ok.all() or not ok.any():
        return v
    last = np.maximum.accumulate(np.where(ok, np.arange(v.size), -1))
    last = np.where(last < 0, int(np.flatnonzero(ok)[0]), last)
    return v[last]


def extend_mask(grid: npt.ArrayLike, mask: npt.ArrayLike, settle: float) -> npt.NDArray[np.bool_]:
    """*mask* and the grid points up to *settle* s after each of its True points.

    >>> extend_mask(np.array([0., 10., 20., 30., 40.]), np.array([False, True, False, False, False]), 15.0).tolist()
    [False, True, True, False, False]
    """
    grid = np.asarray(grid, dtype=float)
    mask = np.asarray(mask, dtype=bool)
    if not mask.any() or settle <= 0.0:
        return mask.copy()
    times = grid[mask]
    idx = np.searchsorted(times, grid, side="right") - 1
    last = np.where(idx >= 0, times[np.clip(idx, 0, None)], -np.inf)
    return (grid - last) <= settle + 1e-9


#: Default gap limit, in multiples of a tag's own median sampling interval, when the spec sets
#: no ``[data] max_gap``; see :func:`default_max_gap`.
GAP_FACTOR = 2.5

#: Gap limit of an exception-reported tag, in multiples of its heartbeat; see :func:`heartbeat_max_gap`.
HEARTBEAT_FACTOR = 1.5


def heartbeat_max_gap(heartbeat: float) -> float:
    """Longest silence of an exception-reported tag that is not missing data: 1.5 x its heartbeat.

    A historian archives a tag when its value leaves the dead band around the last
    archived value, and at the latest at the first scan after the heartbeat has
    elapsed. A tag that is silent for a while is therefore steady, not missing,
    as long as the silence is not longer than the heartbeat plus one scan (with
    jitter). Its median sampling interval says nothing about that: a tag that
    moves often has a short median and long quiet stretches, and the median
    rule (:func:`default_max_gap`) would call every quiet stretch a gap. The
    factor 1.5 covers a scan of up to 60 s with its jitter for heartbeats from
    4 min up, and still calls one missed heartbeat (2 x) a gap. A
    communication loss shorter than that is caught by the historian's
    bad-quality event (the long export's empty ``value``), not by this rule.

    >>> heartbeat_max_gap(600.0)
    900.0
    """
    return HEARTBEAT_FACTOR * float(heartbeat)


def default_max_gap(time: npt.ArrayLike, values: npt.ArrayLike) -> float:
    """Longest gap bridged in a tag when the spec sets no ``max_gap``: 2.5 x its median sampling interval.

    Why this rule: a tag is interpolated between its *own* samples, so a tag
    logged every 30 s in a CSV with 10 s rows (empty cells in between), or with
    jittered timestamps, is used at every grid point; one dropped sample (a
    2 x gap) is bridged as well; two or more dropped samples in a row (3 x or
    more) are missing data, and the grid points inside are NaN: they are not
    scored and the parameter controllers hold there, instead of tracking a
    straight line drawn across the hole. A fixed limit in seconds cannot do this
    for tags of different rates. (Estimation used 1.5 x, which masks the longer
    intervals of irregularly sampled tags; pairing, tracking and validation used
    to bridge every gap.) The twin's *inputs* are still held at their last good
    value across any gap (:attr:`MeasurementView.inputs`), because the twin
    cannot run without them; the view masks the gap like a stoppage.

    Returns ``inf`` (bridge everything) for a tag with fewer than two valid samples.

    >>> default_max_gap([0.0, 10.0, 20.0, 30.0, 100.0], [1.0, 1.0, 1.0, 1.0, 1.0])
    25.0
    """
    t = np.asarray(time, dtype=float)
    y = np.asarray(values, dtype=float)
    t = t[np.isfinite(y) & np.isfinite(t)]
    if t.size < 2:
        return math.inf
    return GAP_FACTOR * float(np.median(np.diff(t)))


WindowName = Literal["training", "validation", "all"]
#: A window of a spec by name, or ``(start, stop)`` in s from the first sample.
WindowArg = Union[WindowName, tuple[float, float]]


def view_tags(spec: Spec, tags: Iterable[str] = ()) -> list[str]:
    """The tags a :class:`MeasurementView` lays on its grid: inputs, outputs, levels, the stoppage tag, *tags*."""
    stoppage = spec.data.stoppage
    needed = [*spec.inputs, *spec.outputs, *(s.tag for s in spec.states),
              *([stoppage.tag] if stoppage is not None else []), *tags]
    return list(dict.fromkeys(needed))


def grid_rows(spec: Spec, window: WindowArg, end: float, lead: float | None) -> tuple[float, float, int, int]:
    """``(start, stop, k_first, k_stop)``: the scored window and the grid's points ``k * sample_time``.

    *end*: the last row's time from the first (s). See :meth:`MeasurementView.from_spec`.
    """
    ts = float(spec.sample_time)
    where = Path(spec.measurements).name
    if isinstance(window, str):
        if window == "all":
            bounds: tuple[float, float] | None = None
        elif window in spec.windows:
            bounds = (float(spec.windows[window][0]), float(spec.windows[window][1]))
        else:
            have = f" (it has: {', '.join(spec.windows)})" if spec.windows else ""
            raise SpecError(f"spec {spec.path} has no [windows] {window} = [start, stop]{have}")
    else:
        bounds = (float(window[0]), float(window[1]))
    if bounds is None:
        bounds = (0.0, end + ts)
    start, stop = bounds
    if stop <= start:
        raise DataError(f"window [{start:g}, {stop:g}) s of {where} ends before it starts")
    first = 0.0 if lead is None else max(0.0, start - float(lead))
    k_first = int(math.ceil(first / ts - 1e-9))
    # points before the window's stop and not after the last row
    k_stop = int(math.ceil(min(stop, end + ts) / ts - 1e-9))
    k_stop = min(k_stop, int(math.floor(end / ts + 1e-9)) + 1)
    if k_stop - k_first > MAX_GRID_POINTS:
        raise DataError(f"{where} spans {end:g} s: on the sample_time = {ts:g} s grid of {spec.path.name} "
                        f"that is {k_stop - k_first:.3g} points (at most {MAX_GRID_POINTS:g})")
    # the points inside [start, stop), counted without building the grid: k * ts in it
    inside, k = 0, max(k_first, int(math.floor((start - 1e-9) / ts)) - 1)
    while k < k_stop and inside < 2 and ts * float(k) < stop - 1e-9:
        inside += ts * float(k) >= start - 1e-9
        k += 1
    if inside < 2:
        raise DataError(f"window [{start:g}, {stop:g}) s of {where} holds {inside} grid "
                        f"point(s) of {ts:g} s between the first sample and the last ({end:g} s)")
    return start, stop, k_first, k_stop


def lay_masks(spec: Spec, grid: npt.NDArray[np.float64], samples: Mapping[str, npt.NDArray[np.float64]],
              in_window: npt.NDArray[np.bool_], skip: float, before: Mapping[str, float] | None = None,
              ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_], npt.NDArray[np.bool_], pd.DataFrame,
                         dict[str, npt.NDArray[np.bool_]], float]:
    """What :meth:`MeasurementView.from_spec` derives from the samples on the grid.

    ``(stopped, stoppage_unknown, input_gap, inputs, scored, settle)``: see the
    attributes of :class:`MeasurementView`. *before*: input tag -> the value its
    hold starts from before the grid's first point (a window of a longer grid,
    :mod:`trackingbox.stream`); without it a leading gap takes the first valid value.
    """
    stoppage = spec.data.stoppage
    stopped = np.zeros(grid.size, dtype=bool)
    unknown = np.zeros(grid.size, dtype=bool)
    settle = 0.0
    if stoppage is not None:
        settle = float(stoppage.settle)
        stopped = stoppage_mask(grid, samples[stoppage.tag], float(stoppage.below), settle)
        # the stoppage tag lost: the plant may have stopped in the gap, so mask it like a stoppage
        unknown = ~np.isfinite(samples[stoppage.tag])
        stopped = stopped | extend_mask(grid, unknown, settle)
    # an input lost: the twin runs on its last good value (held), and the outputs are not compared
    # with it there, nor for the stoppage rule's settle time after it
    input_gap = np.zeros(grid.size, dtype=bool)
    frame: dict[str, npt.NDArray[np.float64]] = {"time": grid}
    for tag, name in spec.inputs.items():
        input_gap |= ~np.isfinite(samples[tag])
        if before is not None and tag in before:
            frame[name] = hold_nan(np.concatenate(([before[tag]], samples[tag])))[1:]
        else:
            frame[name] = hold_nan(samples[tag])
    stopped = stopped | extend_mask(grid, input_gap, settle)
    counted = in_window & (grid >= float(skip) - 1e-9) & ~stopped
    scored = {tag: counted & np.isfinite(samples[tag]) for tag in spec.outputs}
    return stopped, unknown, input_gap, pd.DataFrame(frame), scored, settle


@dataclass(frozen=True)
class MeasurementView:
    """The spec's measurements on the simulation grid, as every stage sees them.

    Built once by :meth:`from_spec`. The grid is ``k * sample_time`` seconds
    from the first row of the CSV (the same grid points for every stage and
    every window), from the first point at or after ``window start - lead``
    (default: the first sample) up to the last point before the window's stop
    that is not after the last row.

    Attributes
    ----------
    source : Path
        The measurements file.
    sample_time : float
        Grid step (s).
    window : tuple of float
        ``[start, stop)`` (s from the first sample): the scored part of the grid.
    grid : ndarray
        Grid times (s from the first sample).
    samples : dict of str to ndarray
        Tag -> values on the grid (:func:`resample`): linear interpolation
        between the tag's own valid samples, or, for an exception-reported tag
        (one with a ``[data] heartbeat``), its last archived value held
        (sample-and-hold: the historian archived the value again as soon as it
        left the dead band, so the held value is right to within the dead band,
        where linear interpolation across a long quiet stretch would smear a
        step over it); NaN outside the samples, inside gaps longer than
        ``max_gap[tag]`` and from a bad-quality event (communication loss) of
        the tag to its next valid sample.
    max_gap : dict of str to float
        Tag -> the gap limit used (s): :func:`heartbeat_max_gap` for a tag with
        a heartbeat, else the spec's ``[data] max_gap`` if set, else
        :func:`default_max_gap` of the tag.
    stopped : ndarray of bool
        Grid points masked like a stoppage: inside a stoppage (``[data]
        stoppage``: its tag below ``below``) or within ``settle`` s after one
        (:func:`stoppage_mask`); where the stoppage tag itself is missing
        (the plant may have stopped unseen: :attr:`stoppage_unknown`) and
        ``settle`` s after; where any input tag is missing
        (:attr:`input_gap`) and ``settle`` s after (0 without a stoppage
        rule). Not scored; the parameter controllers hold there.
    inputs : pandas.DataFrame
        The twin's input table: ``time`` (the grid) and one column per FMU
        input of ``[inputs]``, the last good value held across gaps
        (:func:`hold_nan`).
    scored : dict of str to ndarray of bool
        Output tag -> grid points where the tag counts in a cost: valid sample,
        inside the window, not before ``skip``, not stopped.
    skip : float
        Start-up time left out of the scores (s from the first sample).
    t0 : float
        The first row's ``time`` as read (added to the grid to index the file).
    method : dict of str to {"linear", "hold"}
        Tag -> the reconstruction used.
    input_gap : ndarray of bool
        Grid points where at least one input tag is missing (held in :attr:`inputs`).
    stoppage_unknown : ndarray of bool
        Grid points where the stoppage tag is missing.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from trackingbox.spec import Spec
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = (d / "m.csv").write_text("time,u,y\\n0,1,0\\n10,1,1\\n20,1,2\\n30,1,3\\n")
    >>> spec = Spec(path=d / "s.toml", twin=d / "t.fmu", measurements=d / "m.csv", sample_time=5.0,
    ...             inputs={"u": "u_in"}, outputs={"y": "y_out"})
    >>> v = MeasurementView.from_spec(spec, (10.0, 25.0))
    >>> v.grid.tolist(), v.samples["y"].tolist()
    ([0.0, 5.0, 10.0, 15.0, 20.0], [0.0, 0.5, 1.0, 1.5, 2.0])
    >>> v.scored["y"].tolist()
    [False, False, True, True, True]
    """

    source: Path
    sample_time: float
    window: tuple[float, float]
    grid: npt.NDArray[np.float64] = field(repr=False)
    samples: dict[str, npt.NDArray[np.float64]] = field(repr=False)
    max_gap: dict[str, float]
    stopped: npt.NDArray[np.bool_] = field(repr=False)
    inputs: pd.DataFrame = field(repr=False)
    scored: dict[str, npt.NDArray[np.bool_]] = field(repr=False)
    skip: float = 0.0
    t0: float = 0.0
    method: dict[str, Method] = field(default_factory=dict)
    input_gap: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool), repr=False)
    stoppage_unknown: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool), repr=False)

    # ------------------------------------------------------------------ building

    @classmethod
    def from_spec(cls, spec: Spec, window: WindowArg = "all", *, lead: float | None = None,
                  skip: float = 0.0, tags: Iterable[str] = ()) -> MeasurementView:
        """Read the spec's measurements once and lay them on the grid of *window*.

        Parameters
        ----------
        spec : trackingbox.spec.Spec
            The spec: ``measurements``, ``sample_time``, ``inputs``, ``outputs``,
            ``states``, ``windows`` and ``data`` (``max_gap``, ``stoppage``).
        window : {"all", "training", "validation"} or (start, stop)
            The scored window (s from the first sample); ``"all"`` is the whole file.
        lead : float, optional
            History before the window's start to put on the grid (a lead-in that
            is simulated, not scored); default: everything from the first sample.
        skip : float
            Grid points before this time are not scored (a start-up hold).
        tags : iterable of str
            Extra tags to resample (besides inputs, outputs, states and the
            stoppage tag).

        Raises
        ------
        SpecError
            The spec has no window of that name.
        DataError
            The file is unreadable, a tag is missing from it (did-you-mean), or
            the window holds fewer than two grid points.
        """
        ts = float(spec.sample_time)
        where = Path(spec.measurements).name
        needed = view_tags(spec, tags)
        table = read_table(spec.measurements, required=needed, allow_nan=True)
        empty = [tag for tag in needed if not np.isfinite(table[tag].to_numpy(dtype=float)).any()]
        if empty:
            raise DataError(f"{_n(len(empty), 'tag')} of {where} {'has' if len(empty) == 1 else 'have'} no value "
                            f"at all (every cell empty): {', '.join(map(repr, empty))}")
        t_abs = table["time"].to_numpy(dtype=float)
        t0 = float(t_abs[0])
        end = float(t_abs[-1]) - t0
        start, stop, k_first, k_stop = grid_rows(spec, window, end, lead)
        grid = ts * np.arange(k_first, k_stop, dtype=float)
        in_window = (grid >= start - 1e-9) & (grid < stop - 1e-9)
        rule = spec.data.max_gap
        breaks = table.attrs.get("breaks") or {}
        samples: dict[str, npt.NDArray[np.float64]] = {}
        gaps: dict[str, float] = {}
        methods: dict[str, Method] = {}
        for tag in needed:
            column = table[["time", tag]]
            heartbeat = spec.data.heartbeat_of(tag)
            if heartbeat is not None:
                gap, methods[tag] = heartbeat_max_gap(heartbeat), "hold"
            else:
                gap = float(rule) if rule is not None else default_max_gap(t_abs, column[tag].to_numpy(dtype=float))
                methods[tag] = "linear"
            gaps[tag] = gap
            # a copy: the column alone, not a view keeping the resampled frame's 2-column block alive
            samples[tag] = resample(column, t0 + grid, max_gap=None if math.isinf(gap) else gap,
                                    method=methods[tag], breaks={tag: breaks.get(tag, ())})[tag] \
                .to_numpy(dtype=float, copy=True)
        stopped, unknown, input_gap, frame, scored, settle = lay_masks(spec, grid, samples, in_window, skip)
        view = cls(source=Path(spec.measurements), sample_time=ts, window=(start, stop), grid=grid,
                   samples=samples, max_gap=gaps, stopped=stopped, inputs=frame, scored=scored,
                   skip=float(skip), t0=t0, method=methods, input_gap=input_gap, stoppage_unknown=unknown)
        if input_gap.any() or unknown.any():
            log.info("measurement view of %s: %d grid points with an input missing (inputs held), %d with the "
                     "stoppage tag missing; masked like a stoppage (+%g s settle)", where, int(input_gap.sum()),
                     int(unknown.sum()), settle)
        log.debug("measurement view of %s: %d grid points from %g s, window [%g, %g) s, gap limits %s",
                  where, grid.size, grid[0], start, stop, gaps)
        return view

    # ------------------------------------------------------------------ reading

    @property
    def in_window(self) -> npt.NDArray[np.bool_]:
        """Grid points inside ``[start, stop)`` of :attr:`window`."""
        return (self.grid >= self.window[0] - 1e-9) & (self.grid < self.window[1] - 1e-9)

    @property
    def lead(self) -> int:
        """Number of grid points before the window's start (the lead-in)."""
        return int(np.count_nonzero(self.grid < self.window[0] - 1e-9))

    def values(self, tag: str) -> npt.NDArray[np.float64]:
        """The tag's samples on the grid (NaN where missing or in a long gap)."""
        try:
            return self.samples[tag]
        except KeyError:
            raise DataError(f"tag {tag!r} is not in the measurement view of {self.source.name}"
                            f"{did_you_mean(tag, list(self.samples))}") from None

    def scored_values(self, tag: str) -> npt.NDArray[np.float64]:
        """The tag's samples with NaN wherever it is not scored (:attr:`scored`)."""
        if tag not in self.scored:
            raise DataError(f"tag {tag!r} is not an output tag of the measurement view of {self.source.name}"
                            f"{did_you_mean(tag, list(self.scored))}")
        return np.where(self.scored[tag], self.values(tag), np.nan)

    def filled(self, tag: str) -> npt.NDArray[np.float64]:
        """The tag's samples filled across gaps (:func:`fill_nan`), for FMU inputs."""
        return fill_nan(self.values(tag))

    def gaps(self, tag: str) -> list[tuple[float, float]]:
        """``(first, last)`` grid times of each run of missing samples of *tag* (:func:`nan_spans`)."""
        return nan_spans(pd.Series(self.values(tag)), self.grid)

    def to_frame(self, *, scored: bool = False) -> pd.DataFrame:
        """``time`` (the grid) and one column per tag, as a table.

        With *scored*, output tags are NaN where they are not scored
        (:meth:`scored_values`); other tags are as in :attr:`samples`.
        """
        frame: dict[str, npt.NDArray[np.float64]] = {"time": self.grid}
        for tag in self.samples:
            frame[tag] = self.scored_values(tag) if scored and tag in self.scored else self.samples[tag]
        return pd.DataFrame(frame)

    def scored_counts(self) -> dict[str, int]:
        """Number of scored grid points per output tag."""
        return {tag: int(mask.sum()) for tag, mask in self.scored.items()}
