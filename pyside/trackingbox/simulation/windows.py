"""The simulation service's windows: a twin run over a window of the measurements.

:class:`WindowData` is one window of the spec's measurement view on the simulation grid
(:func:`load_windows`), :class:`Problem` everything a worker needs to run the twin on it
(:func:`problem_from_spec`; picklable, no open FMU), and :func:`simulate_window` (with
:func:`simulate_window_sensitivities`) the run, its warm-up through the measured history included, on the
process's cached model (:mod:`.models`). Estimation's cost, the diagnosis's residuals and the
identifiability checks all simulate through here.
"""
from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..data import MeasurementView
from ..errors import (
    DataError,
    EstimationError,
    SimulationError,
    SpecError,
    unknown_name,
)
from ..fmu import read_info
from ..sensitivity import simulate_sensitivities
from ..supervise import note_phase
from .models import cached_model

if TYPE_CHECKING:
    from ..spec import Spec

log = logging.getLogger(__name__)

#: Default warm-up before each window (s): the run starts this long before the window and goes
#: through the measured history, unscored, so that slow states (tank temperatures, time constants of
#: hours) follow the data into the window. Shortened to the history that exists: no run starts
#: before the data's first sample (nor inside an input gap); the run then starts from the FMU's own
#: initial state, or from its steady state with ``[data] initial = "steady"``.
DEFAULT_WARMUP = 4 * 3600.0
#: Each output tag needs at least this many valid samples in each window.
MIN_VALID_SAMPLES = 20


# --------------------------------------------------------------------------- problem


@dataclass(frozen=True)
class WindowData:
    """One window of measurements on the simulation grid.

    Attributes
    ----------
    name
        ``"training"`` or ``"validation"``.
    start, stop
        Window bounds in seconds from the first sample, ``[start, stop)``.
    time
        Grid times (s from the first sample), step ``sample_time``.
    inputs
        FMU input name -> values on the grid (no NaN).
    measured
        Output tag -> measured values on the grid; NaN where a sample is excluded
        from the cost (missing, long gap, stoppage, lead-in).
    lead
        Number of grid points before ``start`` (the lead-in through the measured
        history, simulated but not scored).
    """

    name: str
    start: float
    stop: float
    time: np.ndarray
    inputs: dict[str, np.ndarray]
    measured: dict[str, np.ndarray]
    lead: int = 0

    def valid_counts(self) -> dict[str, int]:
        """Number of samples of each output tag that enter the cost."""
        return {tag: int(np.isfinite(v).sum()) for tag, v in self.measured.items()}


@dataclass(frozen=True)
class Problem:
    """Everything a worker needs to evaluate the cost: picklable, no open FMU.

    Attributes
    ----------
    twin
        Path of the twin FMU.
    names, start, lower, upper
        Estimated parameters, start values and bounds (spec order).
    fixed
        Known parameters held at these values.
    outputs
        Output tag -> FMU output name.
    sample_time
        Grid step (s).
    warmup
        Warm-up asked for before each window (s), a multiple of ``sample_time``: the
        measured history run through, unscored (shortened to the history that exists).
    initial
        Where a run without history starts: ``"model"`` (the FMU's own initial
        state) or ``"steady"`` (its steady state with the inputs there): the spec's
        ``[data] initial``.
    inputs
        How measured inputs reach the FMU between samples, ``"linear"`` or
        ``"hold"``: the spec's ``[data] inputs``.
    """

    twin: Path
    names: tuple[str, ...]
    start: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    fixed: dict[str, float]
    outputs: dict[str, str]
    sample_time: float
    warmup: float
    initial: str = "model"
    inputs: str = "linear"
    #: Slow states carried through the history (:func:`carried_states`): a run over a window whose start
    #: an earlier window's run covers starts them at their values there; a steady start holds them.
    carry: tuple[str, ...] = ()


def window_setup(problem: Problem, window: WindowData, x: npt.ArrayLike
                 ) -> tuple[dict[str, float], float, np.ndarray, pd.DataFrame | None]:
    """What a run of the twin over *window* with parameter vector *x* starts from.

    Returns the parameter values (the fixed ones and *x*), the length of a run
    before the window's first grid point (always 0: no FMU runs before the data
    it is given), the window's grid from its first point (lead-in included), and
    the input table.

    The run keeps the data's clock: the input table's times, and the model's
    ``time``, are seconds from the first sample of the data, so the run starts
    at :func:`run_start`, the window's first grid point. A model whose equations
    use ``time`` (a drift or a fouling that diagnosis adds) then sees the same
    time on every window and in tracking.
    """
    values = np.asarray(x, dtype=float)
    parameters = dict(problem.fixed)
    parameters.update({name: float(v) for name, v in zip(problem.names, values)})
    t0 = run_start(problem, window)
    grid = window.time - window.time[0]
    frame: dict[str, np.ndarray] = {"time": t0 + grid}
    for name, series in window.inputs.items():
        frame[name] = series
    inputs = pd.DataFrame(frame) if window.inputs else None
    return parameters, 0.0, grid, inputs


def run_start(problem: Problem, window: WindowData) -> float:
    """Model time at which a run over *window* starts: its first grid point (lead-in included).

    Times are the data's clock (s from the first sample), see :func:`window_setup`;
    never before the first sample.
    """
    return float(window.time[0])


def warmup_used(window: WindowData) -> float:
    """Seconds of measured history a run over *window* goes through before the window (its lead-in)."""
    return float(window.start - window.time[0])


def _phase(problem: Problem, window: WindowData, t0: float) -> Any:
    """``note`` for :meth:`FMUModel.simulate`: names the warm-up for the watchdog while the run is in it."""
    label = (f"the warm-up before the {window.name} window of the twin {problem.twin.name} "
             f"(t = {t0:g} to {window.start:g} s, not scored)")
    end = float(window.start)

    def note(t: float) -> None:
        note_phase(label if t <= end + 1e-9 * max(1.0, abs(end)) else f"the {window.name} window")

    return note


def simulate_window(problem: Problem, window: WindowData, x: npt.ArrayLike,
                    tolerance: float = 1e-6, history: tuple[WindowData, ...] = ()) -> dict[str, np.ndarray]:
    """Simulate the twin over *window* with parameter vector *x*.

    Runs from the window's first grid point (its warm-up through the measured
    history, then the window; from the FMU's initial state or its steady state
    there, ``problem.initial``); returns output tag -> simulated values on the
    window's grid (lead-in included). While the run is in the warm-up the
    watchdog's error line says so. *tolerance*: the solver's relative tolerance
    (tighter for finite differences that must resolve small changes). The
    ``problem.carry`` states start at their values in the run over a window of
    *history* that covers this run's start (:func:`carried_states`), else at
    their own start values; a steady start holds them there.
    """
    parameters, offset, grid, inputs = window_setup(problem, window, x)
    if problem.carry:
        parameters.update(carried_states(problem, window, x, history, tolerance))
        problem = replace(problem, outputs={**problem.outputs, **{_CARRY + s: s for s in problem.carry}})
    t0 = run_start(problem, window)
    stop = t0 + offset + float(grid[-1])
    model = cached_model(problem.twin, tolerance)
    try:
        note_phase(f"the start of the {window.name} window's run of the twin {problem.twin.name} (t = {t0:g} s)")
        result = model.simulate(
            start_time=t0,
            stop_time=stop,
            output_interval=problem.sample_time,
            inputs=inputs,
            parameters=parameters,
            outputs=list(dict.fromkeys(problem.outputs.values())),
            input_rule=problem.inputs,
            initial=problem.initial,
            note=_phase(problem, window, t0) if t0 < window.start else None,
            hold=problem.carry,
        )
    finally:
        note_phase()
    t = np.asarray(result["time"], dtype=float)
    out: dict[str, np.ndarray] = {}
    for tag, name in problem.outputs.items():
        y = np.asarray(result[name], dtype=float)
        if not np.all(np.isfinite(y)):
            raise SimulationError(f"twin {problem.twin.name} gave non-finite values of {name!r}")
        out[tag] = np.interp(t0 + offset + grid, t, y)
    if problem.carry:
        _remember(problem, window, x, t0 + offset + grid, {s: out.pop(_CARRY + s) for s in problem.carry})
    return out


# --------------------------------------------------------------------------- carried states

_CARRY = "__carry_"
#: The carried states' trajectories of the last runs: (twin, window, its first grid time, x) -> (time, values).
_RUNS: dict[tuple[str, str, float, bytes], tuple[np.ndarray, dict[str, np.ndarray]]] = {}
_RUNS_KEPT = 32


def _key(problem: Problem, window: WindowData, x: npt.ArrayLike) -> tuple[str, str, float, bytes]:
    return (str(problem.twin), window.name, float(window.time[0]), np.asarray(x, dtype=float).tobytes())


def _remember(problem: Problem, window: WindowData, x: npt.ArrayLike, time: np.ndarray,
              values: dict[str, np.ndarray]) -> None:
    _RUNS[_key(problem, window, x)] = (np.asarray(time, dtype=float), values)
    while len(_RUNS) > _RUNS_KEPT:
        _RUNS.pop(next(iter(_RUNS)))


def carried_states(problem: Problem, window: WindowData, x: npt.ArrayLike, history: tuple[WindowData, ...],
                   tolerance: float = 1e-6) -> dict[str, float]:
    """The ``problem.carry`` states' values at the start of a run over *window*, from the history before it.

    A slow state (a scale that grows over hours above a dry-solids onset, a deposit) is the plant's
    history: a run that starts inside the record must start it where the same twin, at the same *x*,
    had it at that time, not at its start value (the entry's clean surface) nor at a steady state (a
    scale with a wash-off time of a day is far from one). Taken from the run over the window of
    *history* whose run covers this run's start (the training window's run for a validation run that
    begins inside it), made here unless a run of it at *x* was just made; a state a restart or a wash
    removes in that history is removed by the effect's own law in that run (the scale decays below its
    onset). A run no other run covers (the first window; a gap in the data between the windows) starts
    the states at their own start values (empty result).
    """
    t0 = run_start(problem, window)
    earlier = [w for w in history if w is not window and float(w.time[0]) < t0 <= float(w.time[-1])]
    if not earlier:
        if any(float(w.time[0]) < t0 for w in history if w is not window):  # a gap in the data between
            log.info("%s window: no other run covers its start at t = %g s; %s start at their start values",
                     window.name, t0, ", ".join(problem.carry))
        return {}
    before = min(earlier, key=lambda w: float(w.time[0]))
    if _key(problem, before, x) not in _RUNS:
        simulate_window(problem, before, x, tolerance, tuple(w for w in history if w is not window))
    time, values = _RUNS[_key(problem, before, x)]
    return {s: float(np.interp(t0, time, v)) for s, v in values.items()}


def simulate_window_sensitivities(problem: Problem, window: WindowData, x: npt.ArrayLike
                                  ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """:func:`simulate_window` with the outputs' exact sensitivities w.r.t. the estimated parameters.

    One run of the twin with the forward sensitivity equations
    (:func:`trackingbox.sensitivity.simulate_sensitivities`, scaled by the bound
    ranges); returns output tag -> values and output tag -> ``d value / d x``
    (shape ``(len(grid), n_parameters)``) on the window's grid (lead-in included).
    """
    parameters, offset, grid, inputs = window_setup(problem, window, x)
    t0 = run_start(problem, window)
    stop = t0 + offset + float(grid[-1])
    model = cached_model(problem.twin)
    if problem.initial != "model":
        raise SimulationError(f"exact sensitivities start at zero, from the FMU's own initial state; a run from "
                              f"the steady state ([data] initial = {problem.initial!r}) uses finite differences")
    run = simulate_sensitivities(model, wrt=problem.names, scales=problem.upper - problem.lower,
                                 start_time=t0, stop_time=stop, output_interval=problem.sample_time,
                                 inputs=inputs, parameters=parameters, outputs=list(problem.outputs.values()),
                                 input_rule=problem.inputs)
    at = t0 + offset + grid
    values: dict[str, np.ndarray] = {}
    slopes: dict[str, np.ndarray] = {}
    for tag, name in problem.outputs.items():
        values[tag] = np.interp(at, run.time, run.outputs[name])
        slopes[tag] = np.stack([np.interp(at, run.time, column) for column in run.sensitivities[name].T], axis=1)
    return values, slopes


# --------------------------------------------------------------------------- from a spec


def _get(obj: Any, name: str, default: Any = None) -> Any:
    if obj is None:
        return default
    if isinstance(obj, Mapping):
        return obj.get(name, default)
    return getattr(obj, name, default)




def _spans(time_s: np.ndarray, bad: np.ndarray) -> list[tuple[float, float]]:
    spans: list[tuple[float, float]] = []
    i = 0
    n = len(bad)
    while i < n:
        if bad[i]:
            j = i
            while j + 1 < n and bad[j + 1]:
                j += 1
            spans.append((float(time_s[i]), float(time_s[j])))
            i = j + 1
        else:
            i += 1
    return spans


def coarsen(window: WindowData, stride: int) -> WindowData:
    """Every *stride*-th grid point of *window*, for a cheaper cost in the global search.

    The window's start stays on the coarse grid. Inputs are the centred moving
    mean over *stride* samples (so the coarser input sampling does not pick
    single noisy samples); measured outputs are taken as they are (the cost
    averages over them anyway).

    >>> w = WindowData("training", 20.0, 60.0, np.arange(0.0, 60.0, 10.0), {"u": np.arange(6.0)},
    ...                {"y": np.array([np.nan, np.nan, 2.0, 3.0, 4.0, 5.0])}, lead=2)
    >>> c = coarsen(w, 2)
    >>> c.time.tolist(), c.inputs["u"].tolist(), c.lead
    ([0.0, 20.0, 40.0], [0.0, 1.5, 3.5], 1)
    """
    if stride <= 1:
        return window
    first = window.lead % stride
    index = np.arange(first, len(window.time), stride)

    def smooth(v: np.ndarray) -> np.ndarray:
        half = stride // 2
        lo = np.clip(index - half, 0, len(v))
        hi = np.clip(index - half + stride, 0, len(v))
        csum = np.concatenate(([0.0], np.cumsum(v)))
        return (csum[hi] - csum[lo]) / (hi - lo)

    return WindowData(
        window.name, window.start, window.stop, window.time[index],
        {k: smooth(np.asarray(v, dtype=float)) for k, v in window.inputs.items()},
        {k: np.asarray(v, dtype=float)[index] for k, v in window.measured.items()},
        window.lead // stride,
    )


def _after_input_gaps(spec: Spec, view: MeasurementView) -> int:
    """Index of the first lead-in point after the last input gap before the window (0: none)."""
    cut = 0
    for tag in spec.inputs:
        bad_lead = np.flatnonzero(~np.isfinite(view.values(tag)[:view.lead]))
        if bad_lead.size:
            cut = max(cut, int(bad_lead[-1]) + 1)
    return cut


def _lead_in(spec: Spec, name: str, lead: float) -> tuple[MeasurementView, int]:
    """The window's view and the index its run starts at (see :func:`load_windows`).

    The run starts *lead* seconds before the window, after the last input gap. A run that starts from
    the twin's steady state (``[data] initial = "steady"``) does not start inside a stoppage
    (``data.stoppage``: the tag below its threshold): a stopped plant is not at the steady state of its
    stopped inputs (an evaporator whose feed stops while its steam stays on boils dry; its model has no
    steady state there). The run then starts the stoppage rule's ``settle`` time (at least one sample)
    before that stoppage began, and runs through it as the plant did: the stoppage tag lags the inputs
    that stop the plant (a measured flow behind its set-point), so its last sample above the threshold
    may already have the inputs stopped, and ``settle`` is the spec's own measure of how long a stoppage
    disturbs the plant. Where that time is not in the data (they begin stopped) or an input gap lies
    between, the start stays where it was.
    """
    view = MeasurementView.from_spec(spec, name, lead=lead)
    cut = _after_input_gaps(spec, view)
    stoppage = spec.data.stoppage
    if spec.data.initial != "steady" or stoppage is None:
        return view, cut
    below = float(stoppage.below)
    ts = float(spec.sample_time)
    margin = max(float(stoppage.settle), ts)
    window_start = float(view.grid[view.lead]) if view.lead < view.grid.size else float(view.grid[-1])

    def stopped(v: MeasurementView) -> npt.NDArray[np.bool_]:
        level = v.values(stoppage.tag)
        return np.isfinite(level) & (level < below)

    def index(v: MeasurementView, at: float) -> int:
        return int(np.searchsorted(v.grid, at - 1e-6 * ts))

    down = stopped(view)
    if not down[cut]:
        return view, cut
    t_asked = t = float(view.grid[cut])
    began = t
    while True:
        if t < float(view.grid[0]) - 1e-6 * ts:  # before this view: lay a longer one
            view = MeasurementView.from_spec(spec, name, lead=window_start - t + ts)
            down = stopped(view)
        k = index(view, t)
        if not down[k]:
            break
        first = k
        while first > 0 and down[first - 1]:
            first -= 1
        if first == 0:
            if float(view.grid[0]) <= 0.0:  # the data begin stopped: no running sample before it
                log.info("%s window: the run starts at t = %g s inside a stoppage (%s below %g) the data begin "
                         "in: no running sample before it to start from", name, t_asked, stoppage.tag, below)
                return MeasurementView.from_spec(spec, name, lead=lead), cut
            view = MeasurementView.from_spec(spec, name, lead=window_start - float(view.grid[0]) + margin)
            down = stopped(view)
            continue
        began = float(view.grid[first])
        t = max(began - margin, 0.0)
    start, k_asked = index(view, t), index(view, t_asked)
    if any(not np.all(np.isfinite(view.values(tag)[start:k_asked + 1])) for tag in spec.inputs):
        log.info("%s window: the run starts at t = %g s inside a stoppage (%s below %g); an input gap lies "
                 "between it and a running sample before it", name, t_asked, stoppage.tag, below)
        return MeasurementView.from_spec(spec, name, lead=lead), cut
    log.info("%s window: its warm-up would start at t = %g s inside a stoppage (%s below %g since t = %g s), "
             "where the twin has no steady state to start from; it starts at t = %g s, the stoppage rule's "
             "settle time before", name, t_asked, stoppage.tag, below, began, float(view.grid[start]))
    return view, start


def load_windows(spec: Spec, *, warmup: float | None = None) -> tuple[WindowData, WindowData]:
    """Cut the training and validation windows out of the spec's measurement view.

    Each window is a :class:`~trackingbox.data.MeasurementView` (same grid,
    gap rule, stoppage mask and scored samples as tracking and validation).
    A window that starts after the first sample gets a *lead-in*: up to
    ``warmup`` seconds of the measured inputs before it (never across an input
    gap), simulated but not part of the cost, so the twin's slow states follow
    the real history into the window. Where there is less history (a window at
    the first sample has none) the warm-up is shortened to what exists: no run
    starts before the first sample (:func:`warmup_used` says how long it was).
    A run from the twin's steady state (``[data] initial = "steady"``) whose
    warm-up would start inside a stoppage starts the stoppage rule's ``settle``
    time before that stoppage began instead, a longer warm-up (a stopped plant
    has no steady state to start from).

    Parameters
    ----------
    spec
        A loaded spec.
    warmup
        Warm-up before each window (s); default :data:`DEFAULT_WARMUP`.

    Raises
    ------
    DataError
        A tag is missing from the measurements, an input has no valid value
        at all, or an output tag has too few valid samples. An input missing
        over part of a window is held at its last good value and the outputs
        are not scored there (the view masks it like a stoppage).
    """
    where = Path(spec.measurements).name
    windows = _get(spec, "windows")
    lead_s = DEFAULT_WARMUP if warmup is None else float(warmup)
    out = []
    for name in ("training", "validation"):
        span = _get(windows, name)
        if span is None:
            raise SpecError(f"spec {getattr(spec, 'path', '')} has no [windows] {name} = [start, stop]")
        start, stop = float(span[0]), float(span[1])
        try:
            view, cut = _lead_in(spec, name, lead_s)
        except DataError as exc:
            raise DataError(f"{name} window: {exc}; estimation needs at least {MIN_VALID_SAMPLES} samples") \
                from None
        grid = view.grid
        n_lead = view.lead
        n_window = grid.size - n_lead
        grid = grid[cut:]
        lead = n_lead - cut
        problems = []
        inputs = {}
        for tag, fmu_name in spec.inputs.items():
            # through a gap the twin runs on the input's last good value (the view holds it) and the
            # outputs there are masked like a stoppage; only an input with no value at all is refused
            v = view.inputs[fmu_name].to_numpy(dtype=float)[cut:]
            if not np.isfinite(v).all():
                problems.append(f"input tag {tag!r} in {where} has no valid value in the {name} window "
                                f"[{start:g}, {stop:g}) s or before it ({n_window} samples); the twin "
                                f"cannot be simulated without it")
            elif view.input_gap.size and (gap := view.input_gap[cut:] & ~np.isfinite(view.values(tag)[cut:])).any():
                spans = ", ".join(f"{a:g}-{b:g} s" for a, b in _spans(grid, gap)[:5])
                log.info("input tag %r in %s is missing in the %s window at %s: held at its last good value, "
                         "outputs masked there", tag, where, name, spans)
            inputs[fmu_name] = v
        n_stopped = int((view.stopped & view.in_window).sum())
        measured = {}
        for tag in spec.outputs:
            v = view.scored_values(tag)[cut:]  # NaN: missing, long gap, stoppage, lead-in
            n_ok = int(np.isfinite(v).sum())
            if n_ok < MIN_VALID_SAMPLES:
                problems.append(
                    f"output tag {tag!r} has {n_ok} valid samples in the {name} window "
                    f"[{start:g}, {stop:g}) s after removing NaN, long gaps and stoppages "
                    f"({n_stopped} stoppage samples); estimation needs at least "
                    f"{MIN_VALID_SAMPLES}"
                )
            measured[tag] = v
        if problems:
            raise DataError("; ".join(problems))
        out.append(WindowData(name, start, stop, grid, inputs, measured, lead))
    return out[0], out[1]


def problem_from_spec(spec: Spec, *, warmup: float | None = None) -> Problem:
    """Build the picklable :class:`Problem` of a loaded spec.

    Checks that every estimated and fixed parameter and every input/output name
    exists in the twin (did-you-mean on a miss) and that ``min <= start <= max``.
    """
    info = read_info(spec.twin)
    variables = {v.name: v for v in info.variables}
    where = f"twin {Path(spec.twin).name}"
    problems = []
    params = list(spec.parameters)
    if not params:
        raise EstimationError(f"spec {getattr(spec, 'path', '')} has no [[parameters]] to estimate")
    tunable = [v.name for v in info.variables if v.causality == "parameter"]
    names, start, lower, upper = [], [], [], []
    for p in params:
        name = _get(p, "name")
        if name not in variables:
            problems.append(unknown_name("parameter", name, tunable, where))
        lo, hi, s = float(_get(p, "min")), float(_get(p, "max")), float(_get(p, "start"))
        if not (lo < hi):
            problems.append(f"parameter {name!r}: min {lo:g} must be below max {hi:g}")
        elif not (lo <= s <= hi):
            problems.append(f"parameter {name!r}: start {s:g} is outside [{lo:g}, {hi:g}]")
        names.append(name)
        start.append(s)
        lower.append(lo)
        upper.append(hi)
    fixed = {str(k): float(v) for k, v in dict(_get(spec, "fixed", {}) or {}).items()}
    for name in fixed:
        if name not in variables:
            problems.append(unknown_name("fixed parameter", name, tunable, where))
    fmu_inputs = [v.name for v in info.variables if v.causality == "input"]
    for tag, name in spec.inputs.items():
        if name not in variables or variables[name].causality != "input":
            problems.append(unknown_name(f"input (for tag {tag!r})", name, fmu_inputs, where))
    for tag, name in spec.outputs.items():
        if name not in variables:
            problems.append(unknown_name(f"output (for tag {tag!r})", name, list(variables), where))
    carry = carried_names(info, tuple(getattr(_get(spec, "data"), "carry", ()) or ()), problems, where)
    if problems:
        raise SpecError("; ".join(problems))
    dt = float(spec.sample_time)
    w = DEFAULT_WARMUP if warmup is None else float(warmup)
    if w < 0:
        raise EstimationError(f"warm-up must be >= 0 s, got {w:g}")
    w = math.ceil(w / dt - 1e-9) * dt
    data = _get(spec, "data")
    return Problem(
        twin=Path(spec.twin),
        names=tuple(names),
        start=np.array(start),
        lower=np.array(lower),
        upper=np.array(upper),
        fixed=fixed,
        outputs=dict(spec.outputs),
        sample_time=dt,
        warmup=w,
        initial=str(_get(data, "initial", "model") or "model"),
        inputs=str(_get(data, "inputs", "linear") or "linear"),
        carry=carry,
    )


def carried_names(info: Any, carry: tuple[str, ...], problems: list[str], where: str) -> tuple[str, ...]:
    """The twin's continuous states the spec's ``[data] carry`` names: each name a state, or an array of
    states (``R`` for ``R[1]``, ``R[2]``, ...); a name that is neither is a problem."""
    md = getattr(info, "model_description", None)
    states = [d.variable.derivative.name for d in (md.derivatives if md is not None else ())
              if d.variable.derivative is not None]
    out: list[str] = []
    for name in carry:
        found = [s for s in states if s == name or re.fullmatch(re.escape(name) + r"\[\d+\]", s)]
        if not found:
            problems.append(unknown_name("state to carry ([data] carry)", name, states, where))
        out += found
    return tuple(out)
