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

Modules: :mod:`.table` (reading), :mod:`.series` (series on a grid), :mod:`.view` (the measurement
view).

Modules: :mod:`.table` (reading), :mod:`.series` (series on a grid), :mod:`.view` (the
measurement view).
"""
from __future__ import annotations

from .series import (
    GAP_FACTOR,
    HEARTBEAT_FACTOR,
    Method,
    default_max_gap,
    extend_mask,
    fill_nan,
    heartbeat_max_gap,
    hold_nan,
    nan_spans,
    resample,
    stoppage_mask,
    window,
)
from .table import (
    CHUNK_ROWS,
    LONG_COLUMNS,
    MAX_GRID_POINTS,
    MAX_MAGNITUDE,
    NA_VALUES,
    clean_chunks,
    read_table,
)
from .view import (
    MeasurementView,
    WindowArg,
    WindowName,
    grid_rows,
    lay_masks,
    view_tags,
)

__all__ = [
    "NA_VALUES",
    "MAX_MAGNITUDE",
    "MAX_GRID_POINTS",
    "CHUNK_ROWS",
    "clean_chunks",
    "read_table",
    "LONG_COLUMNS",
    "Method",
    "resample",
    "window",
    "nan_spans",
    "stoppage_mask",
    "fill_nan",
    "hold_nan",
    "extend_mask",
    "GAP_FACTOR",
    "HEARTBEAT_FACTOR",
    "heartbeat_max_gap",
    "default_max_gap",
    "WindowName",
    "WindowArg",
    "view_tags",
    "grid_rows",
    "lay_masks",
    "MeasurementView",
]
