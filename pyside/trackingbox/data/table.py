"""Reading a measurement or input table (CSV, wide or a historian's long export): :func:`read_table`,
every problem named with its file, column and line; big files read in chunks (:func:`clean_chunks`).
"""
from __future__ import annotations

import csv
import logging
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..errors import DataError, did_you_mean

if TYPE_CHECKING:
    pass


log = logging.getLogger(__name__)

#: Cells that mean "no value" (read as NaN, not as a non-numeric cell).
NA_VALUES = ("", "NaN", "nan", "NAN", "NA", "N/A", "n/a", "null", "NULL", "None", "#N/A")

_MAX_LISTED = 3  # cells listed per column in a message


def _fmt(t: float) -> str:
    return f"{t:g} s"


def count_text(count: int, noun: str) -> str:
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
        problems.append(f"column 'time' in {where} has {count_text(rows.size, 'empty value')}, first on line {_line(int(rows[0]))}")
    return numeric, t0


def _check_time_order(t: npt.NDArray[np.float64], where: str, problems: list[str]) -> None:
    inf = np.flatnonzero(np.isinf(t))
    if inf.size:
        problems.append(f"column 'time' in {where} has {count_text(inf.size, 'infinite value')}, first on line "
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
                        f"({count_text(dup.size, 'duplicate')} in all)")
    if back.size:
        i = int(valid[back[0] + 1])
        j = int(valid[back[0]])
        problems.append(f"column 'time' in {where} goes backwards: line {_line(i)} has {_fmt(t[i])} after "
                        f"{_fmt(t[j])} on line {_line(j)} ({count_text(back.size, 'decrease')} in all)")


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


def csv_header(path: Path) -> list[str] | None:
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
        header = csv_header(path)
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
            problems.append(f"{kind} {c!r} in {where} has {count_text(rows.size, 'NaN value')}{span}")
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
        problems.append(f"column 'tag' in {where} has {count_text(empty_tag.size, 'empty value')}, "
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
            problems.append(f"{kind} {name!r} in {where} has {count_text(int(na[rows].sum()), 'bad-quality value')} "
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
