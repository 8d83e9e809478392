"""The tracking loop: step the twin beside the plant data and adjust its parameters.

:func:`track` runs the twin FMU through the measurement period on the spec's
``sample_time`` grid. At each sample ``t_k`` it

1. reads the twin's simulated sensors (and, in lockstep, those of an
   *untracked* twin: same FMU, same inputs, same state compensation, parameters
   frozen at their start values);
2. updates one parameter controller per ``[[pairs]]`` entry (setpoint = the
   measured tag, process value = the mapped twin variable, output = the
   parameter) and one :class:`~.controllers.StateCompensator` per
   ``[[states]]`` entry;
3. writes one CSV row (so the output is on disk as it is produced and memory
   stays flat);
4. sets the new parameter values and correction flows and integrates both
   twins to ``t_{k+1}``.

The controllers hold (output frozen, no integration) during the start-up hold
``t < tracking.hold_until``, while their measured tag or simulated variable is
missing (NaN, long gaps masked by ``data.max_gap``), during a flow stoppage
(``data.stoppage``: ``tag < below``, plus ``settle`` seconds after it) and for
``recovery_hold`` seconds after a solver failure. State compensation keeps
running through start-up hold and stoppages (it protects the twin's tanks)
and holds only while its own level measurement is missing.

Checkpoints (JSON, every ``checkpoint_every`` steps and at the end) hold the
step index, the CSV length, controller and compensator states, metric
accumulators and, for model-exchange FMUs, the continuous state vectors of both
twins. ``resume=True`` truncates the CSV to the checkpoint and continues. For
co-simulation FMUs, whose states are not accessible, the twins are rebuilt by
*replaying* the recorded parameter and correction trajectory from the CSV.

A :class:`~trackingbox.errors.SimulationError` during a step is logged, the
twin is re-initialised from its last good state (the continuous states after
the previous step, or a replay) and the step retried with the controllers on
hold; if it fails again the twin is cold-started at that time (fresh
initialisation). Rows already written are never lost.

The streamed CSV cannot be written atomically; its valid length is the one
recorded in the last checkpoint, and the summary files (``checkpoint.json``,
``result.json``) are written atomically.
"""
from __future__ import annotations

import csv
import json
import logging
import math
import time as _time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..data import stoppage_mask
from ..errors import DataError, SimulationError, SpecError, unknown_name
from ..io import write_text_atomic
from .controllers import Scaling, ScaledPI, SlidingMode, StateCompensator, direction_from_gain
from .tuning import pair_settings

log = logging.getLogger(__name__)

Window = Literal["training", "validation", "all"]

#: Output files written into ``out_dir``.
CSV_NAME = "tracking.csv"
CHECKPOINT_NAME = "checkpoint.json"
RESULT_NAME = "result.json"
_CHECKPOINT_VERSION = 1
#: Sliding-mode boundary layer (% of the variable span) when a pair asks for it.
SLIDING_PHI = 5.0

__all__ = [
    "TrackingResult", "VariableResult", "ParameterResult", "TrackingEvent", "track",
    "CSV_NAME", "CHECKPOINT_NAME", "RESULT_NAME",
]


# --------------------------------------------------------------------------- results

@dataclass(frozen=True)
class VariableResult:
    """Fit of one tracking variable over the metric window (after the start-up hold).

    NRMSE = RMSE / range of the measurement (same definition as
    :func:`trackingbox.estimation.nrmse`), over samples where the measurement
    is valid and not inside a stoppage.
    """

    nrmse_untracked: float
    nrmse_tracked: float
    samples: int


@dataclass(frozen=True)
class ParameterResult:
    """Trajectory summary of one tracking parameter (or correction flow) over the run."""

    final: float
    min: float
    max: float
    lower: float
    upper: float


@dataclass(frozen=True)
class TrackingEvent:
    """Something the runtime did on its own: a hold, a recovery, a cold start."""

    time: float
    kind: str
    message: str


@dataclass(frozen=True)
class TrackingResult:
    """Outcome of :func:`track`.

    Attributes
    ----------
    csv : Path
        The streamed trajectory file.
    window : tuple of float
        ``[start, stop)`` (s from the first sample) the metrics were taken over.
    variables : dict
        Tag -> :class:`VariableResult`.
    parameters : dict
        Parameter name -> :class:`ParameterResult`.
    corrections : dict
        State-compensation input -> :class:`ParameterResult` (kg/s; bounds NaN).
    states : dict
        State tag -> :class:`ParameterResult` of the tracked twin's simulated
        level (final/min/max over the run; bounds NaN), to check that no tank
        empties or overflows.
    seconds : float
        Wall-clock seconds of the run (this call).
    seconds_untracked : float
        Wall-clock seconds spent stepping the untracked twin (a plain simulation
        over the same period with the same step), for overhead figures.
    simulated_seconds : float
        Simulated time covered by this call.
    steps : int
        Rows written (total, including rows from before a resume).
    complete : bool
        False when ``max_steps`` stopped the run early (resume to continue).
    events : tuple of TrackingEvent
    """

    csv: Path
    window: tuple[float, float]
    variables: dict[str, VariableResult]
    parameters: dict[str, ParameterResult]
    corrections: dict[str, ParameterResult]
    states: dict[str, ParameterResult]
    seconds: float
    seconds_untracked: float
    simulated_seconds: float
    steps: int
    complete: bool
    events: tuple[TrackingEvent, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """The ``--json`` document of ``trackingbox track``."""
        return {
            "variables": {t: {"nrmse_untracked": _num(v.nrmse_untracked), "nrmse_tracked": _num(v.nrmse_tracked)}
                          for t, v in self.variables.items()},
            "parameters": {n: {"final": _num(p.final), "min": _num(p.min), "max": _num(p.max)}
                           for n, p in self.parameters.items()},
            "seconds": self.seconds,
        }


def _num(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


# --------------------------------------------------------------------------- helpers

class _Stats:
    """Streaming final/min/max of one signal."""

    def __init__(self) -> None:
        self.final = math.nan
        self.min = math.inf
        self.max = -math.inf

    def add(self, x: float) -> None:
        if math.isfinite(x):
            self.final = x
            self.min = min(self.min, x)
            self.max = max(self.max, x)

    def state(self) -> list[float]:
        return [self.final, self.min, self.max]

    def restore(self, s: Sequence[float]) -> None:
        self.final, self.min, self.max = (float(v) for v in s)


class _Fit:
    """Streaming NRMSE accumulators for one tag (tracked and untracked on the same samples)."""

    def __init__(self) -> None:
        self.n = 0
        self.sse_t = 0.0
        self.sse_u = 0.0
        self.n_u = 0
        self.sum = 0.0
        self.lo = math.inf
        self.hi = -math.inf

    def add(self, meas: float, tracked: float, untracked: float) -> None:
        if not (math.isfinite(meas) and math.isfinite(tracked)):
            return
        self.n += 1
        self.sse_t += (tracked - meas) ** 2
        if math.isfinite(untracked):
            self.n_u += 1
            self.sse_u += (untracked - meas) ** 2
        self.sum += meas
        self.lo = min(self.lo, meas)
        self.hi = max(self.hi, meas)

    def _scale(self) -> float:
        span = self.hi - self.lo
        return span if span > 0.0 else max(abs(self.sum / self.n), 1.0)

    def result(self) -> VariableResult:
        if self.n == 0:
            return VariableResult(math.nan, math.nan, 0)
        s = self._scale()
        tracked = math.sqrt(self.sse_t / self.n) / s
        untracked = math.sqrt(self.sse_u / self.n_u) / s if self.n_u == self.n else math.nan
        return VariableResult(untracked, tracked, self.n)

    def state(self) -> list[float]:
        return [self.n, self.sse_t, self.sse_u, self.n_u, self.sum, self.lo, self.hi]

    def restore(self, s: Sequence[float]) -> None:
        self.n, self.sse_t, self.sse_u, self.n_u, self.sum, self.lo, self.hi = s
        self.n, self.n_u = int(self.n), int(self.n_u)




def _fill(values: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Linear interpolation over NaN, held at the ends (inputs must be finite)."""
    ok = np.isfinite(values)
    if ok.all() or not ok.any():
        return values
    idx = np.arange(values.size)
    return np.interp(idx, idx[ok], values[ok])


def _json_float(x: float | None) -> Any:
    if x is None:
        return None
    return x if math.isfinite(x) else repr(float(x))


def _from_json_float(x: Any) -> float | None:
    if x is None:
        return None
    return float(x)


def _jsonify(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _jsonify(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonify(v) for v in obj]
    if isinstance(obj, float):
        return _json_float(obj)
    return obj


def _unjsonify(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _unjsonify(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_unjsonify(v) for v in obj]
    if isinstance(obj, str) and obj in ("nan", "inf", "-inf"):
        return float(obj)
    return obj


# --------------------------------------------------------------------------- the twin

class _Twin:
    """One FMU run that can be restarted from saved states or a replayed trajectory."""

    def __init__(self, path: Path, *, label: str, base: Mapping[str, float], inputs: pd.DataFrame | None,
                 tolerance: float) -> None:
        from ..fmu import FMUModel

        self.label = label
        self.model = FMUModel(path, tolerance=tolerance)
        self.base = dict(base)
        self.inputs = inputs
        self.me = self.model.interface == "ModelExchange"
        self.stepper: Any = None
        self.applied: dict[str, float] = {}
        self.x: npt.NDArray[np.float64] | None = None  # last good continuous states
        self.x_time = math.nan
        self.step_seconds = 0.0

    def start(self, t: float, values: Mapping[str, float], x: Sequence[float] | None = None) -> None:
        """(Re)initialise at *t* with *values* applied; overwrite the states with *x* if given."""
        self.stepper = self.model.stepper(start_time=t, parameters={**self.base, **values}, inputs=self.inputs)
        self.applied = dict(values)
        if x is not None:
            self.stepper.set_continuous_states(np.asarray(x, dtype=float))
        self._save()

    def _save(self) -> None:
        if self.me:
            self.x = self.stepper.get_continuous_states()
            self.x_time = float(self.stepper.time)

    def get(self, names: Sequence[str]) -> npt.NDArray[np.float64]:
        return self.stepper.get(names)

    def step(self, t_next: float, values: Mapping[str, float]) -> None:
        """Apply the values that changed and integrate to *t_next*."""
        changed = {n: v for n, v in values.items() if self.applied.get(n) != v}
        t0 = _time.perf_counter()
        if changed:
            self.stepper.set(changed)
            self.applied.update(changed)
        self.stepper.step(t_next)
        self.step_seconds += _time.perf_counter() - t0
        self._save()

    def replay(self, t0: float, rows: Iterator[tuple[float, dict[str, float]]]) -> None:
        """Rebuild the run from *t0* by re-applying recorded values: ``(t_next, values)`` per step."""
        first = True
        for t_next, values in rows:
            if first:
                self.start(t0, values)
                first = False
            self.step(t_next, values)
        if first:
            self.start(t0, {})

    def close(self) -> None:
        self.model.close()


# --------------------------------------------------------------------------- set-up

@dataclass
class _Pair:
    tag: str
    fmu_name: str
    parameter: str
    controller: ScaledPI | SlidingMode
    bounds: tuple[float, float]


@dataclass
class _State:
    tag: str
    variable: str
    correction: str
    tracked: StateCompensator
    untracked: StateCompensator


@dataclass
class _Plan:
    grid: npt.NDArray[np.float64]          # s from the first sample
    measured: dict[str, npt.NDArray[np.float64]]
    inputs: pd.DataFrame
    stopped: npt.NDArray[np.bool_]
    metric_window: tuple[float, float]
    columns: list[str]
    read_names: list[str]                  # twin variables read each step (output + state variables)
    out_tags: list[str]                    # tags with a tracked/untracked column, in column order
    tag_var: dict[str, str]
    untracked_table: dict[str, npt.NDArray[np.float64]] | None = None
    events: list[TrackingEvent] = field(default_factory=list)


def _make_controller(spec: Any, pair: Any, measured: npt.NDArray[np.float64]) -> _Pair:
    p = spec.parameter(pair.parameter)
    ts = float(spec.sample_time)
    # the one span/tuning rule, shared with the generated Modelica box
    settings = pair_settings(pair, float(p.min), float(p.max), ts=ts, where=spec.path.name)
    scaling, kp, ti, direction = settings.scaling, settings.kp, settings.ti, settings.direction
    span = scaling.span
    kind = getattr(pair, "controller", "pi")
    if kind == "sliding":
        ctrl: ScaledPI | SlidingMode = SlidingMode.from_pi(scaling, kp=kp, ti=ti, ts=ts, direction=direction,
                                                           p0=p.start, phi=SLIDING_PHI)
    else:
        ctrl = ScaledPI(scaling, kp=kp, ti=ti, ts=ts, direction=direction, p0=p.start)
    log.info("pair %s -> %s: %s kp=%.4g ti=%.4g s (scaled), span=%.4g, %s acting", pair.variable, pair.parameter,
             kind, kp, ti, span, "direct" if direction > 0 else "reverse")
    return _Pair(pair.variable, spec.outputs[pair.variable], pair.parameter, ctrl, (p.min, p.max))


def _check_authority(pair: _Pair, measured: npt.NDArray[np.float64], events: list[TrackingEvent]) -> None:
    """Warn when the parameter's whole range moves the variable by little compared with the data.

    ``|gain|·(p_max - p_min)`` (the controller's span) below 5 % of the measured
    range (1st-99th percentile) means the controller can only correct a small
    part of the error and will sit at a bound: a pairing problem, not a tuning one.
    """
    ok = measured[np.isfinite(measured)]
    if ok.size < 10:
        return
    lo, hi = np.percentile(ok, [1.0, 99.0])
    rng = float(hi - lo)
    span = pair.controller.scaling.span
    if rng > 0.0 and span < 0.05 * rng:
        msg = (f"pair {pair.tag!r} -> {pair.parameter!r}: the parameter's whole range "
               f"[{pair.bounds[0]:g}, {pair.bounds[1]:g}] moves {pair.tag!r} by only {span:.3g} "
               f"against a measured range of {rng:.3g}; the controller will mostly sit at a bound "
               "(consider another pairing)")
        log.warning(msg)
        events.append(TrackingEvent(0.0, "weak-pair", msg))


def _plan(spec: Any, window: Window, untracked: bool | pd.DataFrame) -> _Plan:
    from .. import data

    if not spec.pairs:
        raise SpecError(f"spec {spec.path} has no [[pairs]]; run `trackingbox pair` first or add them")
    table = data.read_table(spec.measurements, allow_nan=True)
    where = Path(spec.measurements).name
    columns = [c for c in table.columns if c != "time"]
    problems = []
    stoppage = spec.data.stoppage
    needed = [*spec.inputs, *(p.variable for p in spec.pairs), *(s.tag for s in spec.states)]
    if stoppage is not None:
        needed.append(stoppage.tag)
    for tag in dict.fromkeys(needed):
        if tag not in columns:
            problems.append(unknown_name("tag", tag, columns, where))
    for pair in spec.pairs:
        if pair.variable not in spec.outputs:
            problems.append(unknown_name("tracking variable", pair.variable, spec.outputs, f"[outputs] of {spec.path}"))
    if problems:
        raise DataError("; ".join(problems))

    t_abs = table["time"].to_numpy(dtype=float)
    t0 = float(t_abs[0])
    end = float(t_abs[-1] - t0)
    ts = float(spec.sample_time)
    if window == "all":
        metric = (0.0, end + ts)
    else:
        if window not in spec.windows:
            raise SpecError(f"spec {spec.path} has no [windows] {window} = [start, stop]"
                            f"{'' if not spec.windows else ' (it has: ' + ', '.join(spec.windows) + ')'}")
        metric = tuple(float(v) for v in spec.windows[window])  # type: ignore[assignment]
    stop = min(end, metric[1])
    n = int(math.floor(stop / ts + 1e-9)) + 1
    if metric[1] <= end:  # [start, stop): do not step onto the window's end
        n = int(math.ceil(metric[1] / ts - 1e-9))
    grid = ts * np.arange(max(n, 2))
    tags = list(dict.fromkeys([*needed, *spec.outputs]))
    tags = [t for t in tags if t in columns]
    sampled = data.resample(table[["time", *tags]], t0 + grid, max_gap=spec.data.max_gap)
    measured = {tag: np.asarray(sampled[tag], dtype=float) for tag in tags}

    inputs = {"time": grid}
    for tag, name in spec.inputs.items():
        v = measured[tag]
        bad = ~np.isfinite(v)
        if bad.all():
            raise DataError(f"input tag {tag!r} in {where} has no valid value between 0 and {grid[-1]:g} s")
        if bad.any():
            log.warning("input tag %r in %s is missing at %d of %d samples; interpolated/held for the twin",
                        tag, where, int(bad.sum()), bad.size)
        inputs[name] = _fill(v)
    stopped = np.zeros(grid.size, dtype=bool)
    if stoppage is not None:
        stopped = stoppage_mask(grid, measured[stoppage.tag], float(stoppage.below), float(stoppage.settle))

    out_tags: list[str] = list(spec.outputs)
    tag_var = dict(spec.outputs)
    for s in spec.states:
        if s.tag not in tag_var:
            out_tags.append(s.tag)
            tag_var[s.tag] = s.variable
    read_names = list(dict.fromkeys(tag_var[t] for t in out_tags))
    cols = ["time"]
    for tag in out_tags:
        cols += [f"measured:{tag}", f"tracked:{tag}", f"untracked:{tag}"]
    cols += [f"parameter:{p.parameter}" for p in spec.pairs]
    cols += [f"correction:{s.correction}" for s in spec.states]
    cols += [f"untracked_correction:{s.correction}" for s in spec.states]
    cols += [f"mode:{p.variable}" for p in spec.pairs]
    untracked_table = None
    if isinstance(untracked, pd.DataFrame):
        if "time" not in untracked.columns:
            raise DataError("the untracked simulation table has no 'time' column")
        ut = untracked["time"].to_numpy(dtype=float)
        untracked_table = {}
        for name in read_names:
            if name not in untracked.columns:
                raise DataError(unknown_name("column", name, untracked.columns, "the untracked simulation table"))
            untracked_table[name] = np.interp(grid, ut, untracked[name].to_numpy(dtype=float))
    return _Plan(grid, measured, pd.DataFrame(inputs), stopped, metric, cols, read_names, out_tags, tag_var,
                 untracked_table)


def _read_rows(path: Path, upto: int, names: Sequence[str], prefix: str, grid: npt.NDArray[np.float64],
               ) -> Iterator[tuple[float, dict[str, float]]]:
    """Recorded values of *names* (columns ``prefix + name``) for rows ``0 .. upto-1``, as replay steps."""
    if upto <= 0:
        return
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        idx = [header.index(prefix[i] + n) for i, n in enumerate(names)]
        for k, row in enumerate(reader):
            if k >= upto:
                break
            yield float(grid[k + 1]), {n: float(row[j]) for n, j in zip(names, idx)}


# --------------------------------------------------------------------------- the loop

def track(
    spec: Any,
    *,
    out_dir: str | Path,
    resume: bool = False,
    progress: Callable[[int, int], None] | None = None,
    max_steps: int | None = None,
    window: Window = "all",
    untracked: bool | pd.DataFrame = True,
    checkpoint_every: int = 200,
    recovery_hold: float | None = None,
    tolerance: float = 1e-6,
) -> TrackingResult:
    """Run the tracking simulator over the spec's measurements.

    Parameters
    ----------
    spec : trackingbox.spec.Spec
        A loaded spec with ``[[pairs]]``.
    out_dir : path
        Where ``tracking.csv``, ``checkpoint.json`` and ``result.json`` go.
    resume : bool
        Continue from ``checkpoint.json`` in *out_dir* (fresh start if there is none).
    progress : callable, optional
        ``progress(rows_done, rows_total)`` after each row.
    max_steps : int, optional
        Stop after this many rows in this call (checkpointed; resume to continue).
    window : {"all", "training", "validation"}
        Window the NRMSE figures are taken over (always after the start-up hold).
        The twin runs from the first sample to the end of this window.
    untracked : bool or pandas.DataFrame
        Run the untracked twin in lockstep (True), skip it (False) or use a
        given simulation (``time`` + the twin variable names of the outputs).
    checkpoint_every : int
        Rows between checkpoints.
    recovery_hold : float, optional
        Seconds the controllers stay on hold after a solver failure; default
        ``10·sample_time``.
    tolerance : float
        Relative solver tolerance of the twins.

    Returns
    -------
    TrackingResult

    Raises
    ------
    SpecError, DataError
        Unusable spec or data (named).
    SimulationError
        The twin failed at the same time even after a cold restart (the rows
        up to that time stay in the CSV).
    """
    from ..spec import check_against_fmu

    wall0 = _time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path = out_dir / CSV_NAME
    ckpt_path = out_dir / CHECKPOINT_NAME
    check_against_fmu(spec)
    plan = _plan(spec, window, untracked)
    grid = plan.grid
    n_rows = grid.size
    ts = float(spec.sample_time)
    hold_until = float(spec.tracking.hold_until)
    recovery_hold = 10.0 * ts if recovery_hold is None else float(recovery_hold)

    pairs = [_make_controller(spec, p, plan.measured[p.variable]) for p in spec.pairs]
    for p in pairs:
        _check_authority(p, plan.measured[p.tag], plan.events)
    states = [_State(s.tag, s.variable, s.correction, StateCompensator(s.gain, ts=ts),
                     StateCompensator(s.gain, ts=ts)) for s in spec.states]
    base = {p.name: p.start for p in spec.parameters}
    base.update(spec.fixed)
    param_names = [p.parameter for p in pairs]
    corr_names = [s.correction for s in states]
    pstats = {n: _Stats() for n in param_names}
    cstats = {n: _Stats() for n in corr_names}
    sstats = {s.tag: _Stats() for s in states}
    fits = {t: _Fit() for t in spec.outputs}
    read = plan.read_names
    ridx = {name: i for i, name in enumerate(read)}
    events = plan.events
    run_untracked = untracked is True

    def event(t: float, kind: str, message: str, level: int = logging.WARNING) -> None:
        log.log(level, "t = %g s: %s", t, message)
        if len(events) < 1000:
            events.append(TrackingEvent(float(t), kind, message))

    twin = _Twin(spec.twin, label="tracked", base=base, inputs=plan.inputs, tolerance=tolerance)
    plain = _Twin(spec.twin, label="untracked", base=base, inputs=plan.inputs, tolerance=tolerance) \
        if run_untracked else None
    k0 = 0
    recovery_until = -math.inf
    missing: dict[str, float | None] = {p.tag: None for p in pairs}
    ckpt: dict[str, Any] | None = None
    if resume and ckpt_path.exists() and csv_path.exists():
        ckpt = _unjsonify(json.loads(ckpt_path.read_text(encoding="utf-8")))
        if ckpt.get("version") != _CHECKPOINT_VERSION or ckpt.get("columns") != plan.columns \
                or not math.isclose(float(ckpt.get("sample_time", -1)), ts):
            raise SpecError(f"checkpoint {ckpt_path} was written for a different spec or version; "
                            "run without --resume to start over")
        if ckpt.get("window") != window or int(ckpt.get("rows_total", -1)) != n_rows:
            raise SpecError(f"checkpoint {ckpt_path} was written for window {ckpt.get('window')!r} "
                            f"({ckpt.get('rows_total')} rows), not {window!r} ({n_rows} rows); resume with "
                            f"--window {ckpt.get('window')} or run without --resume")
    elif resume:
        log.info("no checkpoint in %s; starting from the beginning", out_dir)

    try:
        if ckpt is not None:
            k0 = int(ckpt["rows"])
            with open(csv_path, "r+b") as fh:
                fh.truncate(int(ckpt["csv_bytes"]))
            for p in pairs:
                p.controller.restore(ckpt["controllers"][p.parameter])
            for s in states:
                s.tracked.restore(ckpt["compensators"][s.correction])
                s.untracked.restore(ckpt["untracked_compensators"][s.correction])
            for n in param_names:
                pstats[n].restore(ckpt["parameter_stats"][n])
            for n in corr_names:
                cstats[n].restore(ckpt["correction_stats"][n])
            for n in sstats:
                sstats[n].restore(ckpt["state_stats"][n])
            for t in fits:
                fits[t].restore(ckpt["fits"][t])
            recovery_until = float(ckpt["recovery_until"])
            missing = {k: _from_json_float(v) for k, v in ckpt["missing"].items()}
            for e in ckpt.get("events", []):
                events.append(TrackingEvent(float(e[0]), str(e[1]), str(e[2])))
            t_k = float(grid[k0]) if k0 < n_rows else float(grid[-1])
            applied = {**{n: float(v) for n, v in ckpt["applied"].items()}}
            _restore_twin(twin, ckpt.get("x"), t_k, applied, csv_path, k0, grid,
                          [*param_names, *corr_names],
                          [*(["parameter:"] * len(param_names)), *(["correction:"] * len(corr_names))])
            if plain is not None:
                applied_u = {n: float(v) for n, v in ckpt["applied_untracked"].items()}
                _restore_twin(plain, ckpt.get("x_untracked"), t_k, applied_u, csv_path, k0, grid,
                              corr_names, ["untracked_correction:"] * len(corr_names))
            log.info("resumed at row %d (t = %g s) from %s", k0, t_k, ckpt_path)
            fh_out = open(csv_path, "a", newline="", encoding="utf-8")
            writer = csv.writer(fh_out)
        else:
            start_values = {p.parameter: p.controller.value for p in pairs}
            twin.start(0.0, {**start_values, **{c: 0.0 for c in corr_names}})
            if plain is not None:
                plain.start(0.0, {c: 0.0 for c in corr_names})
            fh_out = open(csv_path, "w", newline="", encoding="utf-8")
            writer = csv.writer(fh_out)
            writer.writerow(plan.columns)
    except BaseException:
        twin.close()
        if plain is not None:
            plain.close()
        raise

    def checkpoint(rows: int, complete: bool) -> None:
        fh_out.flush()
        payload = {
            "version": _CHECKPOINT_VERSION,
            "spec": str(spec.path),
            "sample_time": ts,
            "columns": plan.columns,
            "rows": rows,
            "rows_total": n_rows,
            "window": window,
            "time": float(grid[min(rows, n_rows - 1)]),
            "csv_bytes": fh_out.tell(),
            "complete": complete,
            "controllers": {p.parameter: p.controller.state() for p in pairs},
            "compensators": {s.correction: s.tracked.state() for s in states},
            "untracked_compensators": {s.correction: s.untracked.state() for s in states},
            "parameters": {p.parameter: p.controller.value for p in pairs},
            "applied": dict(twin.applied),
            "applied_untracked": dict(plain.applied) if plain is not None else {},
            "x": twin.x.tolist() if twin.x is not None else None,
            "x_untracked": plain.x.tolist() if plain is not None and plain.x is not None else None,
            "parameter_stats": {n: s.state() for n, s in pstats.items()},
            "correction_stats": {n: s.state() for n, s in cstats.items()},
            "state_stats": {n: s.state() for n, s in sstats.items()},
            "fits": {t: f.state() for t, f in fits.items()},
            "recovery_until": recovery_until,
            "missing": missing,
            "events": [[e.time, e.kind, e.message] for e in events],
        }
        write_text_atomic(ckpt_path, json.dumps(_jsonify(payload), indent=1))

    def safe_step(tw: _Twin, k: int, values: dict[str, float], names: list[str], prefixes: list[str]) -> bool:
        """Step *tw* from row k to k+1; recover from a solver failure. True if it had to recover."""
        t_k, t_next = float(grid[k]), float(grid[k + 1])
        try:
            tw.step(t_next, values)
            return False
        except SimulationError as exc:
            event(t_k, "solver-failure", f"{tw.label} twin failed between {t_k:g} s and {t_next:g} s: {exc}")
        fh_out.flush()
        try:
            if tw.me and tw.x is not None and math.isclose(tw.x_time, t_k, abs_tol=1e-9 * max(1.0, t_k)):
                tw.start(t_k, values, tw.x)
            else:
                tw.replay(0.0, _read_rows(csv_path, k, names, prefixes, grid))
                tw.stepper.set(values)
                tw.applied.update(values)
            tw.step(t_next, values)
            event(t_k, "recovered", f"{tw.label} twin re-initialised from its state at {t_k:g} s and continued")
            return True
        except SimulationError as exc:
            event(t_k, "solver-failure", f"{tw.label} twin failed again after re-initialisation: {exc}")
        tw.start(t_k, values)  # cold start: fresh initialisation at t_k
        tw.step(t_next, values)  # a third failure propagates
        event(t_k, "cold-start", f"{tw.label} twin cold-started (fresh initialisation) at {t_k:g} s")
        return True

    rows_this_call = 0
    complete = True
    k = k0
    try:
        while k < n_rows:
            t = float(grid[k])
            y = twin.get(read)
            yu = plain.get(read) if plain is not None else (
                np.array([plan.untracked_table[n][k] for n in read]) if plan.untracked_table is not None
                else np.full(len(read), np.nan))
            hold_all = t < hold_until - 1e-9 or bool(plan.stopped[k]) or t < recovery_until - 1e-9
            modes = []
            for p in pairs:
                sp = float(plan.measured[p.tag][k])
                pv = float(y[ridx[p.fmu_name]])
                ok = math.isfinite(sp)
                if not ok and missing[p.tag] is None:
                    missing[p.tag] = t
                    event(t, "missing", f"tag {p.tag!r} missing from t = {t:g} s: controller of "
                          f"{p.parameter!r} on hold", logging.INFO)
                elif ok and missing[p.tag] is not None:
                    event(t, "resumed", f"tag {p.tag!r} back at t = {t:g} s after {t - missing[p.tag]:g} s; "
                          f"controller of {p.parameter!r} resumes (bumpless)", logging.INFO)
                    missing[p.tag] = None
                p.controller.update(sp, pv, hold=hold_all)
                modes.append(p.controller.mode)
            corr, corr_u = {}, {}
            for s in states:
                meas = float(plan.measured[s.tag][k])
                level = float(y[ridx[s.variable]])
                sstats[s.tag].add(level)
                corr[s.correction] = s.tracked.update(meas, level)
                corr_u[s.correction] = s.untracked.update(meas, float(yu[ridx[s.variable]])) \
                    if plain is not None else math.nan
            params = {p.parameter: p.controller.value for p in pairs}
            in_metric = plan.metric_window[0] - 1e-9 <= t < plan.metric_window[1] - 1e-9 \
                and t >= hold_until - 1e-9 and not plan.stopped[k]
            row: list[Any] = [t]
            for tag in plan.out_tags:
                j = ridx[plan.tag_var[tag]]
                m = float(plan.measured[tag][k])
                row += [m, float(y[j]), float(yu[j])]
                if in_metric and tag in fits:
                    fits[tag].add(m, float(y[j]), float(yu[j]))
            row += [params[n] for n in param_names]
            row += [corr[n] for n in corr_names]
            row += [corr_u[n] for n in corr_names]
            row += modes
            writer.writerow(row)
            for n in param_names:
                pstats[n].add(params[n])
            for n in corr_names:
                cstats[n].add(corr[n])
            rows_this_call += 1
            if progress is not None:
                progress(k + 1, n_rows)
            if k == n_rows - 1:
                k += 1
                break
            recovered = safe_step(twin, k, {**params, **corr}, [*param_names, *corr_names],
                                  [*(["parameter:"] * len(param_names)), *(["correction:"] * len(corr_names))])
            if plain is not None:
                try:
                    safe_step(plain, k, dict(corr_u), list(corr_names),
                              ["untracked_correction:"] * len(corr_names))
                except SimulationError as exc:
                    # the comparison run is not worth stopping the tracking for
                    event(t, "untracked-abandoned", f"untracked twin failed for good and is dropped "
                          f"(its columns are empty from here on): {exc}")
                    plain.close()
                    plain = None
            if recovered:
                recovery_until = float(grid[k + 1]) + recovery_hold
                event(t, "hold", f"controllers on hold until t = {recovery_until:g} s after the recovery")
            k += 1
            if k % checkpoint_every == 0:
                checkpoint(k, False)
                # a checkpoint is a restart point: re-initialise from the saved states, exactly
                # as a resume would, so a resumed run is identical to an uninterrupted one
                for tw in (twin, plain):
                    if tw is not None and tw.me and tw.x is not None:
                        tw.start(float(grid[k]), dict(tw.applied), tw.x)
            if max_steps is not None and rows_this_call >= max_steps and k < n_rows:
                complete = False
                break
        checkpoint(k, complete)
    finally:
        fh_out.close()
        twin.close()
        if plain is not None:
            plain.close()

    seconds = _time.perf_counter() - wall0
    result = TrackingResult(
        csv=csv_path,
        window=(max(plan.metric_window[0], hold_until), min(plan.metric_window[1], float(grid[-1]) + ts)),
        variables={t: f.result() for t, f in fits.items()},
        parameters={n: ParameterResult(s.final, s.min, s.max, p.bounds[0], p.bounds[1])
                    for (n, s), p in zip(pstats.items(), pairs)},
        corrections={n: ParameterResult(s.final, s.min, s.max, math.nan, math.nan) for n, s in cstats.items()},
        states={n: ParameterResult(s.final, s.min, s.max, math.nan, math.nan) for n, s in sstats.items()},
        seconds=seconds,
        seconds_untracked=plain.step_seconds if plain is not None else math.nan,
        simulated_seconds=float(grid[min(k, n_rows - 1)] - grid[k0]) if k > k0 else 0.0,
        steps=k,
        complete=complete,
        events=tuple(events),
    )
    summary = {**result.to_json(), "complete": complete, "steps": k, "csv": str(csv_path),
               "window": list(result.window),
               "variables_detail": {t: {"samples": v.samples} for t, v in result.variables.items()},
               "corrections": {n: {"final": _num(c.final), "min": _num(c.min), "max": _num(c.max)}
                               for n, c in result.corrections.items()},
               "states": {n: {"final": _num(c.final), "min": _num(c.min), "max": _num(c.max)}
                          for n, c in result.states.items()},
               "events": [[e.time, e.kind, e.message] for e in events]}
    write_text_atomic(out_dir / RESULT_NAME, json.dumps(summary, indent=1))
    return result


def _restore_twin(tw: _Twin, x: Any, t_k: float, applied: dict[str, float], csv_path: Path, rows: int,
                  grid: npt.NDArray[np.float64], names: list[str], prefixes: list[str]) -> None:
    """Put *tw* at ``t_k`` with *applied* values: from saved states, else by replaying the CSV."""
    if x is not None and tw.me:
        tw.start(t_k, applied, x)
    else:
        tw.replay(0.0, _read_rows(csv_path, rows, names, prefixes, grid))
