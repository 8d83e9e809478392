"""Series on a grid: resampling with the gap rule (:func:`resample`), NaN spans, the stoppage mask,
holding and filling missing values, and the default longest gap of a tag.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..errors import DataError

if TYPE_CHECKING:
    pass


log = logging.getLogger(__name__)


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

