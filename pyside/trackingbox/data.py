"""Measurement and input tables: reading, validation, resampling, NaN spans.

A table is a CSV file with a ``time`` column and one numeric column per tag or
FMU input. ``time`` is either seconds (floats) or ISO 8601 timestamps; timestamps
are converted to seconds from the first row and the first timestamp is kept in
``df.attrs["t0"]``.

:func:`read_table` checks everything it can and reports *all* problems of a file
in one :class:`~trackingbox.errors.DataError`, so a user fixes a file in one go.
"""
from __future__ import annotations

import csv
import logging
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from .errors import DataError, did_you_mean

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
                    bad.append(f"{text!r} on line {_line(int(i))}")
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
    valid = np.flatnonzero(~np.isnan(t))
    if valid.size < 2:
        return
    tv = t[valid]
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


def _header(path: Path) -> list[str] | None:
    with path.open(newline="", encoding="utf-8") as fh:
        for row in csv.reader(fh):
            return [c.strip() for c in row]
    return None


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
        na = col.isna().to_numpy()
        values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~na & np.isnan(values))
        if bad.size:
            cells = ", ".join(f"{col.iloc[i]!r} on line {_line(int(i))}" for i in bad[:_MAX_LISTED])
            more = f" (and {bad.size - _MAX_LISTED} more)" if bad.size > _MAX_LISTED else ""
            problems.append(f"{kind} {c!r} in {where} has non-numeric values: {cells}{more}")
        infinite = np.flatnonzero(np.isinf(values))
        if infinite.size:
            problems.append(f"{kind} {c!r} in {where} has infinite values, first on line {_line(int(infinite[0]))}")
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


def resample(df: pd.DataFrame, grid: Sequence[float] | npt.ArrayLike, max_gap: float | None = None) -> pd.DataFrame:
    """Interpolate every column of *df* onto the time *grid*, never across long gaps.

    Method: for each column separately, take only that column's valid (non-NaN)
    samples and interpolate linearly between the two valid samples around each
    grid point. A grid point becomes NaN when

    * it lies before the column's first or after its last valid sample (no
      extrapolation), or
    * the two valid samples around it are more than *max_gap* seconds apart
      (the point is inside a gap; grid points that coincide with a valid sample
      keep that sample's value).

    Parameters
    ----------
    df
        Table with a ``time`` column (s), strictly increasing.
    grid
        Target times (s), increasing.
    max_gap
        Longest span (s) between valid samples that may be bridged; ``None``:
        any gap is bridged.

    Returns
    -------
    pandas.DataFrame
        ``time`` = *grid* and the other columns of *df*, resampled.

    Examples
    --------
    >>> df = pd.DataFrame({"time": [0.0, 10.0, 20.0, 100.0], "T": [0.0, 1.0, 2.0, 10.0]})
    >>> resample(df, [5.0, 15.0, 50.0], max_gap=30.0)["T"].tolist()
    [0.5, 1.5, nan]
    """
    if "time" not in df.columns:
        raise DataError("cannot resample a table without a 'time' column")
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
        if tv.size == 1:
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
        out[c] = res
    result = pd.DataFrame(out)
    result.attrs.update(df.attrs)
    return result


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
