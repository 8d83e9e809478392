"""The MSL's table blocks (``Modelica.Blocks.Sources.CombiTimeTable``, ``Modelica.Blocks.Tables.CombiTable1Dv``
and ``CombiTable1Ds``) with their Modelica meaning, without their C sources.

The blocks call external C functions of ``Modelica/Resources/C-Sources/ModelicaStandardTables.c`` on an
external object built from the table matrix. The embedded backend recognises those calls by name and
builds the interpolation as expressions instead, with the semantics of that C code (MSL 4.0.0):

* time tables: ``y = 0`` before ``startTime``; the table is read at ``t - shiftTime``; constant or linear
  segments (``Smoothness.ConstantSegments``, ``LinearSegments``; rows with equal times are jumps);
  outside the table ``HoldLastPoint``, ``LastTwoPoints`` (linear through the two end rows, also for
  constant segments) or ``NoExtrapolation`` (an error-level assert); every table point is a time event
  (a relation on time, see :mod:`.events`) for constant segments and, unless ``timeEvents`` says
  otherwise, for linear segments; ``getNextTimeEvent`` gives the next table point after ``t``;
* 1-D tables: the same interpolation in the input ``u`` (no events), columns as given.

``Periodic`` extrapolation of time tables repeats the table, with a time event at each period's
end. Refused, naming the construct: tables read from files (``tableOnFile = true``), the spline
options, periodic 1-D tables, and the 2-D tables.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from . import arrays as arr

TIME_VALUE = {"Modelica.Blocks.Tables.Internal.getTimeTableValue",
              "Modelica.Blocks.Tables.Internal.getTimeTableValueNoDer",
              "Modelica.Blocks.Tables.Internal.getTimeTableValueNoDer2"}
TIME_NEXT = "Modelica.Blocks.Tables.Internal.getNextTimeEvent"
TIME_MIN = "Modelica.Blocks.Tables.Internal.getTimeTableTmin"
TIME_MAX = "Modelica.Blocks.Tables.Internal.getTimeTableTmax"
ONE_D_VALUE = {"Modelica.Blocks.Tables.Internal.getTable1DValue",
               "Modelica.Blocks.Tables.Internal.getTable1DValueNoDer",
               "Modelica.Blocks.Tables.Internal.getTable1DValueNoDer2"}
ONE_D_MIN = "Modelica.Blocks.Tables.Internal.getTable1DAbscissaUmin"
ONE_D_MAX = "Modelica.Blocks.Tables.Internal.getTable1DAbscissaUmax"
FUNCTIONS = TIME_VALUE | ONE_D_VALUE | {TIME_NEXT, TIME_MIN, TIME_MAX, ONE_D_MIN, ONE_D_MAX}

TIME_CONSTRUCTOR = "Modelica.Blocks.Types.ExternalCombiTimeTable"
ONE_D_CONSTRUCTOR = "Modelica.Blocks.Types.ExternalCombiTable1D"

# Modelica.Blocks.Types enumerations (ordinals)
LINEAR, CONSTANT = 1, 3
LAST_TWO_POINTS, HOLD_LAST_POINT, PERIODIC, NO_EXTRAPOLATION = 2, 1, 3, 4
NO_TIME_EVENTS = 3
INF = 1e60  # Modelica.Constants.inf of the MSL (ModelicaServices.Machine.inf)


@dataclass
class Table:
    """A table object: the abscissae (numbers), the rows (values, maybe expressions) and its options."""

    kind: str  # "time" | "1d"
    grid: list[float]
    data: np.ndarray  # object array, rows x columns of the matrix
    columns: list[int]
    smoothness: int
    extrapolation: int
    start: Any = 0.0
    shift: Any = 0.0
    time_events: int = 1
    name: str = ""


class TableError(Exception):
    """A table option the embedded backend does not support (the message names it)."""


def _near(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-10 * max(1.0, abs(a), abs(b))


def _linear(x: Any, t0: float, t1: float, y0: Any, y1: Any) -> Any:
    return y0 + (y1 - y0) * (x - t0) / (t1 - t0)


def value(tab: Table, icol: int, x: Any, ge, assert_in_range, floor=None) -> Any:
    """The interpolated value of output column *icol* (1-based) at abscissa *x*.

    *ge(a, b)* builds the relation ``a >= b`` (frozen with an event indicator, or plain); for time
    tables *x* is the time, read at ``x - shift`` and 0 before ``start``. *assert_in_range(lo_ok,
    hi_ok)* records the range check of ``NoExtrapolation``. *floor(e)* (held between events, for
    periodic time tables) gives the period count.
    """
    if not 1 <= icol <= len(tab.columns):
        raise TableError(f"column {icol} of table {tab.name} (it has {len(tab.columns)} output columns)")
    col = int(tab.columns[icol - 1]) - 1
    if not 0 <= col < tab.data.shape[1]:
        raise TableError(f"columns[{icol}] = {col + 1} of table {tab.name}, whose matrix has "
                         f"{tab.data.shape[1]} columns")
    ys = list(tab.data[:, col])
    ts = tab.grid
    n = len(ts)
    t = x - tab.shift if tab.kind == "time" else x
    if n == 1:
        v = ys[0]
    else:
        if tab.extrapolation == PERIODIC:
            if tab.kind != "time" or floor is None:
                raise TableError(f"periodic extrapolation of the 1-D table {tab.name}")
            period = ts[n - 1] - ts[0]
            if not period > 0:
                raise TableError(f"periodic extrapolation of table {tab.name}, whose abscissae span nothing")
            # the time within the period; the period count is held between events (a time event at
            # each period's end), so the segments below switch at events only
            t = t - floor((t - ts[0]) / period) * period
        if tab.extrapolation in (LAST_TWO_POINTS, PERIODIC):
            left = ys[0] if _near(ts[0], ts[1]) else _linear(t, ts[0], ts[1], ys[0], ys[1])
            right = ys[n - 1] if _near(ts[n - 2], ts[n - 1]) else _linear(t, ts[n - 2], ts[n - 1], ys[n - 2], ys[n - 1])
        else:
            left, right = ys[0], ys[n - 1]
            if tab.extrapolation == NO_EXTRAPOLATION:
                assert_in_range(ge(t, ts[0]), ge(ts[n - 1], t))
        v = left
        for i in range(n - 1):
            if tab.smoothness == CONSTANT or _near(ts[i], ts[i + 1]):
                seg = ys[i] if not _near(ts[i], ts[i + 1]) else ys[i + 1]
            else:
                seg = _linear(t, ts[i], ts[i + 1], ys[i], ys[i + 1])
            v = _select(ge(t, ts[i]), seg, v)
        v = _select(ge(t, ts[n - 1]), right, v)
    if tab.kind == "time":
        v = _select(ge(x, tab.start), v, 0.0)
    return v


def next_event(tab: Table, x: Any) -> Any:
    """``getNextTimeEvent``: the first table point (or the start time) after time *x*; INF when none."""
    if tab.time_events == NO_TIME_EVENTS and tab.smoothness != CONSTANT:
        points: list[Any] = [tab.start]
    elif tab.extrapolation == PERIODIC and len(tab.grid) > 1:
        # the points of the period x is in and of the next one
        period = tab.grid[-1] - tab.grid[0]
        k = (ca.floor if not _is_num(x) else np.floor)((x - tab.shift - tab.grid[0]) / period)
        base = tab.grid[0] + k * period + tab.shift
        points = [tab.start] + [base + (g - tab.grid[0]) + j * period for j in (0, 1) for g in tab.grid]
        nxt: Any = INF
        for p in reversed(points[1:]):
            nxt = _select(x < p, p, nxt)
        return _select(x < tab.start, tab.start, nxt)
    else:
        points = [tab.start] + [g + tab.shift for g in tab.grid]
    nxt: Any = INF
    for p in sorted(points, key=lambda q: float(q) if isinstance(q, (int, float)) else 0.0, reverse=True):
        nxt = _select(x < p, p, nxt) if not _is_num(x) or not _is_num(p) else (p if x < p else nxt)
    return nxt


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating))


def _select(cond: Any, a: Any, b: Any) -> Any:
    if isinstance(cond, (bool, np.bool_)) or _is_num(cond):
        return a if bool(cond) else b
    return ca.if_else(cond, a, b)


def from_constructor(kind: str, name: str, args: list[Any], numeric) -> Table:
    """A :class:`Table` from the evaluated arguments of ``ExternalCombiTimeTable(...)`` or
    ``ExternalCombiTable1D(...)``; *numeric(v, what)* turns a value into a number (parameters at
    their start values)."""
    if kind == "time":
        table_name, file_name, matrix, start, columns, smoothness, extrapolation, shift, time_events = args[:9]
    else:
        table_name, file_name, matrix, columns, smoothness, extrapolation = args[:6]
        start = shift = 0.0
        time_events = NO_TIME_EVENTS
    if str(file_name) not in ("NoName", "") or str(table_name) not in ("NoName", ""):
        raise TableError(f"table {name} read from a file (tableOnFile = true)")
    if not arr.is_array(matrix) or len(arr.shape(matrix)) != 2 or 0 in arr.shape(matrix):
        raise TableError(f"table {name}: the table matrix is empty or not a matrix")
    smoothness = int(numeric(smoothness, "smoothness"))
    if smoothness not in (LINEAR, CONSTANT):
        raise TableError(f"table {name}: smoothness other than LinearSegments and ConstantSegments")
    extrapolation = int(numeric(extrapolation, "extrapolation"))
    grid = [numeric(v, f"abscissa of table {name}") for v in matrix[:, 0]]
    if any(b < a for a, b in zip(grid, grid[1:])):
        raise TableError(f"table {name}: the abscissae (first column) are not increasing")
    cols = [int(numeric(c, "columns")) for c in (columns.ravel() if arr.is_array(columns) else [columns])]
    return Table(kind, grid, matrix, cols, smoothness, extrapolation, start, shift,
                 int(numeric(time_events, "timeEvents")), name)


__all__ = ["FUNCTIONS", "Table", "TableError", "from_constructor", "next_event", "value"]
