"""The measurement view every stage reads the measurements through: :class:`MeasurementView`."""
from __future__ import annotations

import logging
import math
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Union

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..errors import DataError, SpecError, did_you_mean

if TYPE_CHECKING:
    from ..spec import Spec


from .series import (
    Method,
    default_max_gap,
    extend_mask,
    fill_nan,
    heartbeat_max_gap,
    hold_nan,
    nan_spans,
    resample,
    stoppage_mask,
)
from .table import MAX_GRID_POINTS, count_text, read_table

log = logging.getLogger(__name__)

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


#: Measurement tables read in this process, newest last: (path, size, mtime, inode, tags) -> table.
_TABLES: OrderedDict[tuple[object, ...], pd.DataFrame] = OrderedDict()
#: How many tables :func:`read_measurements` keeps.
TABLES_KEPT = 2
#: Inside how many :func:`kept_tables` blocks this process is (0: every read parses the file).
_KEEPING = [0]


@contextmanager
def kept_tables() -> Iterator[None]:
    """Keep the measurement tables read inside the block (:func:`read_measurements`); forget them after it.

    Used where one file is read many times over and does not change meanwhile (a diagnosis, and
    the worker processes of its pools, :mod:`trackingbox.diagnose.parallel`).
    """
    _KEEPING[0] += 1
    try:
        yield
    finally:
        _KEEPING[0] -= 1
        if not _KEEPING[0]:
            _TABLES.clear()


def keep_tables() -> None:
    """Keep the tables read from now on, for the rest of this process (a diagnosis's worker process)."""
    _KEEPING[0] += 1


def read_measurements(path: str | Path, tags: Iterable[str]) -> pd.DataFrame:
    """:func:`~trackingbox.data.table.read_table` of a measurement file (NaN allowed); inside
    :func:`kept_tables`, read once.

    A diagnosis lays the same file on windows again and again (each screened candidate's patched
    spec reads the spec's measurements: on the single-effect evaporator 81 reads, 16 s of a 193 s
    diagnosis run in one process); the parsed table is kept under the file's path, size, modification time and inode
    and the tags asked for, so a rewritten file is read again. The caller gets a copy.
    """
    p = Path(path)
    required = tuple(dict.fromkeys(tags))
    if not _KEEPING[0]:
        return read_table(p, required=required, allow_nan=True)
    try:
        st = p.stat()
    except OSError:
        return read_table(p, required=required, allow_nan=True)  # its own error for a missing file
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns, st.st_ino, required)
    table = _TABLES.get(key)
    if table is None:
        table = read_table(p, required=required, allow_nan=True)
        _TABLES[key] = table
        while len(_TABLES) > TABLES_KEPT:
            _TABLES.popitem(last=False)
    else:
        _TABLES.move_to_end(key)
    return table.copy(deep=True)

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
        table = read_measurements(spec.measurements, needed)
        empty = [tag for tag in needed if not np.isfinite(table[tag].to_numpy(dtype=float)).any()]
        if empty:
            raise DataError(f"{count_text(len(empty), 'tag')} of {where} {'has' if len(empty) == 1 else 'have'} no value "
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
