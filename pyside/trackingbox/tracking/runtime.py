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
   twins to ``t_{k+1}``: with ``substeps`` the tracked twin in parts of the
   sample, the parameter controllers advancing after each part (see
   :func:`track`). A small change is carried by the tracked twin's
   integrator (no re-initialisation; ``carry`` in :func:`track`).

The controllers hold (output frozen, no integration) during the start-up hold
``t < tracking.hold_until``, while their measured tag or simulated variable is
missing (NaN, long gaps masked by ``data.max_gap``), during a flow stoppage
(``data.stoppage``: ``tag < below``, plus ``settle`` seconds after it) and for
``recovery_hold`` seconds after a solver failure. State compensation keeps
running through start-up hold and stoppages (it protects the twin's tanks)
and holds only while its own level measurement is missing.

The loop is a :class:`TrackingLoop` whose parts (the parameter controllers,
the state compensation, the tracked and untracked twins, the output stream)
each save and restore their own state (``state_dict()`` /
``load_state_dict()``). A checkpoint (JSON, every ``checkpoint_every`` steps
and at the end) is the loop's state: the row index and the parts' states
(controller and compensator states, the applied values and, for
model-exchange FMUs, the continuous states of both twins, the CSV length and
the summaries). ``resume=True`` truncates the CSV to the checkpoint and
continues. For co-simulation FMUs, whose states are not accessible, the twins
are rebuilt by *replaying* the recorded parameter and correction trajectory
from the CSV. Every checkpoint is also a restart point of an uninterrupted
run, so a run resumed from a checkpoint writes the same bytes.

The data (grid, per-tag samples with the gap rule, stoppage mask, the twin's
input table and the samples scored per tag) come from the spec's
:class:`~trackingbox.data.MeasurementView`, as in estimation and validation.

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
import ctypes
import json
import logging
import math
import os
import time as _time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..checkpoint import CheckpointFile
from ..data import MeasurementView
from ..errors import DataError, SimulationError, SpecError, unknown_name
from ..io import write_text_atomic
from ..stream import MARGIN_ROWS, WINDOW_ROWS, WindowedMeasurements, percentile_range
from .controllers import Interpolation, ScaledPI, SlidingMode, StateCompensator
from .tuning import pair_settings

if TYPE_CHECKING:
    from ..spec import Spec

log = logging.getLogger(__name__)

Window = Literal["training", "validation", "all"]
#: How the parameter controllers and compensators are integrated with the twin (see :func:`track`)
ControllerMode = Literal["discrete", "continuous"]

#: Output files written into ``out_dir``.
CSV_NAME = "tracking.csv"
CHECKPOINT_NAME = "checkpoint.json"
RESULT_NAME = "result.json"
_CHECKPOINT_VERSION = 7  # 7: band columns; 6: controller mode; 5: carried integrator (carry, hold flag); 4: sub-steps; 3: error interpolation in the controllers; 2: one entry per part
#: Sliding-mode boundary layer (% of the variable span) when a pair asks for it.
SLIDING_PHI = 5.0

__all__ = [
    "TrackingResult", "VariableResult", "ParameterResult", "TrackingEvent", "TrackingLoop", "track",
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
    restarts, carried : int
        Changes of the tracked twin's parameters and corrections over the run
        (resumed parts included) that re-initialised its integrator, and
        changes it carried (see ``carry`` in :func:`track`).
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
    restarts: int = 0
    carried: int = 0

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
            if x < self.min:  # min() and max() as comparisons: called per sample and signal
                self.min = x
            if x > self.max:
                self.max = x

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
        if meas < self.lo:
            self.lo = meas
        if meas > self.hi:
            self.hi = meas

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

#: The twins' native steppers reuse CVODE's last Jacobian for the first step after a restart
#: (:meth:`~trackingbox.native.NativeStepper.keep_jacobian`) instead of evaluating a new one, one
#: right-hand side per state (29 on heat production). Measured 2026-11-27, heat production, 1 day,
#: 8 sub-steps (right-hand-side evaluations of the tracked twin, tracking run alone): the default
#: (carried) path 609k -> 358k, the restart path (``carry=0``) 2.79M -> 0.86M; the plain twin run
#: makes 188k. Not after a forced restart (a hold's edges, a recovery: large changes), where a new one
#: is evaluated (:meth:`~trackingbox.native.NativeStepper.forget_jacobian`), so a run whose only restarts
#: are those (the heat exchanger) is unchanged bit for bit. Accuracy (2 h case of ``tests/test_tracking_carry.py`` at rtol 1e-8 against the restart
#: path at 1e-10): the restart path 1.65e-5 of a range either way; at rtol 1e-6 over the day the
#: restart path moves by 7e-6 of a range. The Python path (``TRACKINGBOX_NATIVE=0``) cannot.
KEEP_JACOBIAN = True

def _native_stepper() -> type:
    """:class:`~trackingbox.native.NativeStepper` (imported on first use), or a class nothing is an instance of."""
    global _NATIVE
    if _NATIVE is None:
        try:
            from ..native import NativeStepper
        except ImportError:  # pragma: no cover - the module is part of the package
            NativeStepper = type("_NoNative", (), {})
        _NATIVE = NativeStepper
    return _NATIVE


_NATIVE: type | None = None


class _Twin:
    """One FMU run that can be restarted from saved states or a replayed trajectory."""

    def __init__(self, path: Path, *, label: str, base: Mapping[str, float], inputs: pd.DataFrame | None,
                 tolerance: float, recorded: Mapping[str, str],
                 extrapolate: Mapping[str, tuple[float, float]] | None = None,
                 rename: Mapping[str, str] | None = None) -> None:
        from ..fmu import FMUModel

        self.label = label
        #: value name -> the FMU's variable that takes it (the tracked parameters' inputs of an inputs twin,
        #: :func:`~trackingbox.generate.inputs_twin.inputs_twin`); names not in it are the FMU's own
        self.rename = dict(rename or {})
        #: parameter -> bounds: applied over [t_k, t_k+1] as the mean of the controller's ramp over
        #: that sample, predicted from the last one (see :meth:`_applied`)
        self.extrapolate = dict(extrapolate or {})
        #: the values given for the previous step (before extrapolation)
        self.given: dict[str, float] = {}
        #: value name -> CSV column holding what was applied (for a replay)
        self.recorded = dict(recorded)
        self.model = FMUModel(path, tolerance=tolerance)
        self.base = dict(base)
        self.inputs = inputs
        self.me = self.model.interface == "ModelExchange"
        self.stepper: Any = None
        self.applied: dict[str, float] = {}
        self.x: npt.NDArray[np.float64] | None = None  # last good continuous states
        self.x_time = math.nan
        self.step_seconds = 0.0
        #: value name -> the largest change the integrator carries (no restart); empty: restart on every change
        self.carry_limits: dict[str, float] = {}
        #: restart the integrator at the next change whatever its size (set after a hold, a recovery)
        self.force_restart = False
        #: changes that re-initialised the integrator / that it carried, over all runs of this twin
        self.restarts = 0
        self.carried = 0
        #: the variables the loop reads after every step (read with the step, :meth:`get`), and their values
        self.read_names: list[str] | None = None
        self.y: npt.NDArray[np.float64] | None = None
        self._read_key: tuple[str, ...] = ()
        #: the solver's maximum step (None: the input table's smallest interval); a windowed run gives
        #: the whole grid's, which its input table, one window of it, may not show
        self.max_step: float | None = None
        #: rows -> an input table from the first row past row *rows* (a windowed run's replay from 0),
        #: None: :attr:`inputs` covers the run
        self.replay_inputs: Callable[[int], pd.DataFrame] | None = None

    def start(self, t: float, values: Mapping[str, float], x: Sequence[float] | None = None) -> None:
        """(Re)initialise at *t* with *values* applied; overwrite the states with *x* if given."""
        self._count()
        self.y = None
        self.stepper = self.model.stepper(start_time=t, parameters=self.fmu_values({**self.base, **values}),
                                          inputs=self.inputs, max_step=self.max_step,
                                          carry=bool(self.carry_limits) and self.me, keep_jacobian=KEEP_JACOBIAN)
        self.applied = dict(values)
        if x is not None:
            self.stepper.set_continuous_states(np.asarray(x, dtype=float))
        self._save()

    def _count(self) -> None:
        """Add the finished stepper's restarts and carried changes to the twin's counts."""
        st = self.stepper
        if st is not None and hasattr(st, "carried"):
            self.restarts += st.restarts
            self.carried += st.carried
            st.restarts = st.carried = 0

    def counts(self) -> tuple[int, int]:
        """``(restarts, carried)``: changes that re-initialised the integrator and changes it carried."""
        self._count()
        return self.restarts, self.carried

    def _small(self, changed: Mapping[str, float]) -> bool:
        """True if every change is within its carry limit (and none is forced to restart)."""
        limits = self.carry_limits
        if self.force_restart or not limits:
            return False
        applied = self.applied
        for name, value in changed.items():
            limit = limits.get(name)
            old = applied.get(name)
            if limit is None or old is None or not abs(value - old) <= limit:
                return False
        return True

    def fmu_name(self, name: str) -> str:
        """The FMU variable that takes the value *name* (see :attr:`rename`)."""
        return self.rename.get(name, name)

    def fmu_values(self, values: Mapping[str, float]) -> dict[str, float]:
        """*values* under the FMU's names (see :attr:`rename`)."""
        if not self.rename:
            return dict(values)
        return {self.rename.get(n, n): v for n, v in values.items()}

    def _save(self) -> None:
        if self.me:
            self.x = self.stepper.get_continuous_states()
            self.x_time = float(self.stepper.time)

    def get(self, names: Sequence[str]) -> npt.NDArray[np.float64]:
        """Current values of *names* (those of :attr:`read_names` as read with the last step)."""
        if names is self.read_names and self.y is not None:
            return self.y.copy()
        return self.stepper.get(names)

    def _applied(self, values: Mapping[str, float]) -> dict[str, float]:
        """The values to apply over the coming sample (:meth:`step` then remembers the given ones).

        A parameter in :attr:`extrapolate` with the controller's value ``p_k``
        at ``t_k`` (linear error interpolation) is applied as
        ``p_k + (p_k - p_k-1)/2``, clamped to its bounds: the compiled box's
        parameter ramps over the sample, and this is the ramp's mean predicted
        from the previous sample, so the twin does not see the parameter one
        half sample late.
        """
        out = dict(values)
        given = self.given
        for name, (lo, hi) in self.extrapolate.items():
            if name in values and name in given:
                p = float(values[name])
                x = p + 0.5 * (p - given[name])
                out[name] = lo if x < lo else hi if x > hi else x  # min(max(x, lo), hi), NaN kept
        return out

    def step(self, t_next: float, values: Mapping[str, float], code: int | None = None) -> None:
        """Apply the values that changed and integrate to *t_next*.

        *code*: the native stepper's ``tbn_advance`` for this step already ran
        (in a batch of rows, :class:`_NativeRows`) and returned *code*; finish it.
        """
        given = {n: float(v) for n, v in values.items()}
        if self.extrapolate:
            values = self._applied(values)
        applied = self.applied
        changed = {n: v for n, v in values.items() if applied.get(n) != v}
        t0 = _time.perf_counter()
        stepper = self.stepper
        self.y = None
        if changed and self.force_restart and code is None and hasattr(stepper, "forget_jacobian"):
            stepper.forget_jacobian()  # a large change (start-up hold's end, a hold, a recovery): a new Jacobian
        if code is not None or (self.read_names is not None and isinstance(stepper, _native_stepper())):
            # the native stepper sets, steps and reads the states and the read variables in one C call
            fchanged = self.fmu_values(changed) if self.rename else changed
            try:
                if code is not None:
                    x, y = stepper.finish_advance(code, fchanged, t_next, self._read_key)
                else:
                    x, y = stepper.advance(fchanged, t_next, self._read_key,
                                           restart=not changed or not self._small(changed))
            except BaseException:
                if changed and stepper.holds(fchanged):  # the set went through, the step failed
                    self.force_restart = False
                    applied.update(changed)
                raise
            if changed:
                self.force_restart = False
                applied.update(changed)
            self.step_seconds += _time.perf_counter() - t0
            self.given = given
            self.x, self.x_time, self.y = x, float(stepper.time), y
            return
        if changed:
            stepper.set(self.fmu_values(changed), restart=not self._small(changed))
            self.force_restart = False
            applied.update(changed)
        stepper.step(t_next)
        self.step_seconds += _time.perf_counter() - t0
        self.given = given
        if self.me:  # _save
            self.x = stepper.get_continuous_states()
            self.x_time = float(stepper.time)

    def replay(self, t0: float, rows: Iterator[tuple[float, dict[str, float]]]) -> None:
        """Rebuild the run from *t0* by re-applying recorded values: ``(t_next, values)`` per step."""
        first = True
        self.given = {}
        forced, self.force_restart = self.force_restart, False
        for t_next, values in rows:
            if first:
                self.start(t0, values)
                first = False
            self.step(t_next, values)
        if first:
            self.start(t0, {})
        self.force_restart = forced

    def replay_csv(self, csv_path: Path, rows: int, grid: npt.NDArray[np.float64]) -> None:
        """Rebuild the run from 0 by replaying the values recorded in the first *rows* rows of the CSV."""
        if self.replay_inputs is None:
            self.replay(0.0, _read_rows(csv_path, rows, self.recorded, grid))
            return
        current = self.inputs
        self.inputs = self.replay_inputs(rows)  # from row 0: the one place a windowed run holds that much
        try:
            self.replay(0.0, _read_rows(csv_path, rows, self.recorded, grid))
        finally:
            self.inputs = current
        self.stepper.replace_inputs(current)

    def state_dict(self) -> dict[str, Any]:
        """The values applied and, for model exchange, the continuous states after the last step."""
        return {"applied": dict(self.applied), "given": dict(self.given),
                "x": self.x.tolist() if self.x is not None else None, "force_restart": self.force_restart,
                "counts": list(self.counts())}

    def load_state_dict(self, state: Mapping[str, Any], *, t: float, csv_path: Path, rows: int,
                        grid: npt.NDArray[np.float64], substeps: int = 1) -> None:
        """Put the twin at *t* as :meth:`state_dict` saved it: from its states, else by replaying the CSV."""
        x = state.get("x")
        self.force_restart = bool(state.get("force_restart", False))
        counts = [int(c) for c in state.get("counts", (0, 0))]
        if x is None and substeps > 1:
            log.warning("%s twin: no states in the checkpoint; the replay applies the recorded values once "
                        "a sample, not the %d sub-steps of each, so the resumed run is close to, not "
                        "identical with, an uninterrupted one", self.label, substeps)
        if x is not None and self.me:
            self.start(t, {n: float(v) for n, v in state["applied"].items()}, x)
            self.given = {n: float(v) for n, v in state.get("given", {}).items()}
        else:
            self.replay_csv(csv_path, rows, grid)
        self._count()  # the replay's own changes are not the run's
        self.restarts, self.carried = counts

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
    view: MeasurementView                  # grid, samples, stoppage mask, twin inputs, scored samples
    columns: list[str]
    read_names: list[str]                  # twin variables read each step (output + state variables)
    out_tags: list[str]                    # tags with a tracked/untracked column, in column order
    tag_var: dict[str, str]
    untracked_table: dict[str, npt.NDArray[np.float64]] | None = None
    events: list[TrackingEvent] = field(default_factory=list)


def _make_controller(spec: Any, pair: Any, measured: npt.NDArray[np.float64],
                     interpolation: Interpolation = "linear") -> _Pair:
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
        ctrl = ScaledPI(scaling, kp=kp, ti=ti, ts=ts, direction=direction, p0=p.start, interpolation=interpolation)
    log.info("pair %s -> %s: %s kp=%.4g ti=%.4g s (scaled), span=%.4g, %s acting", pair.variable, pair.parameter,
             kind, kp, ti, span, "direct" if direction > 0 else "reverse")
    return _Pair(pair.variable, spec.outputs[pair.variable], pair.parameter, ctrl, (p.min, p.max))


def _check_authority(pair: _Pair, measured: tuple[int, float, float], events: list[TrackingEvent]) -> None:
    """Warn when the parameter's whole range moves the variable by little compared with the data.

    ``|gain|·(p_max - p_min)`` (the controller's span) below 5 % of the measured
    range (1st-99th percentile) means the controller can only correct a small
    part of the error and will sit at a bound: a pairing problem, not a tuning one.
    """
    n, lo, hi = measured  # percentile_range of the variable's samples
    if n < 10:
        return
    rng = float(hi - lo)
    span = pair.controller.scaling.span
    if rng > 0.0 and span < 0.05 * rng:
        msg = (f"pair {pair.tag!r} -> {pair.parameter!r}: the parameter's whole range "
               f"[{pair.bounds[0]:g}, {pair.bounds[1]:g}] moves {pair.tag!r} by only {span:.3g} "
               f"against a measured range of {rng:.3g}; the controller will mostly sit at a bound "
               "(consider another pairing)")
        log.warning(msg)
        events.append(TrackingEvent(0.0, "weak-pair", msg))


def _plan(spec: Spec, window: Window, untracked: bool | pd.DataFrame, view: MeasurementView | None = None,
          stream: WindowedMeasurements | None = None) -> _Plan:
    if not spec.pairs:
        raise SpecError(f"spec {spec.path} has no [[pairs]]; run `trackingbox pair` first or add them")
    problems = []
    for pair in spec.pairs:
        if pair.variable not in spec.outputs:
            problems.append(unknown_name("tracking variable", pair.variable, spec.outputs, f"[outputs] of {spec.path}"))
    if problems:
        raise DataError("; ".join(problems))
    if view is None:
        view = MeasurementView.from_spec(spec, window, skip=float(spec.tracking.hold_until))
    elif view.grid.size == 0 or view.grid[0] != 0.0 or view.skip != float(spec.tracking.hold_until):
        raise DataError(f"the measurement view given to track() must start at the first sample and skip the "
                        f"start-up hold ({spec.tracking.hold_until:g} s): build it with "
                        f"MeasurementView.from_spec(spec, {window!r}, skip=spec.tracking.hold_until)")
    where = view.source.name
    grid = view.grid
    for tag in spec.inputs:
        if stream is not None:
            missing, size, last = stream.input_missing[tag], stream.n_rows, stream.grid[-1]
        else:
            bad = ~np.isfinite(view.values(tag))
            missing, size, last = int(bad.sum()), bad.size, grid[-1]
        if missing == size:
            raise DataError(f"input tag {tag!r} in {where} has no valid value between 0 and {last:g} s")
        if missing:
            log.warning("input tag %r in %s is missing at %d of %d samples; interpolated/held for the twin",
                        tag, where, missing, size)

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
    return _Plan(view, cols, read_names, out_tags, tag_var, untracked_table)


def _read_rows(path: Path, upto: int, columns: Mapping[str, str], grid: npt.NDArray[np.float64],
               ) -> Iterator[tuple[float, dict[str, float]]]:
    """Recorded values (name -> its CSV column) of rows ``0 .. upto-1``, as replay steps ``(t_next, values)``."""
    if upto <= 0:
        return
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        idx = {name: header.index(column) for name, column in columns.items()}
        for k, row in enumerate(reader):
            if k >= upto:
                break
            yield float(grid[k + 1]), {n: float(row[j]) for n, j in idx.items()}


# --------------------------------------------------------------------------- the parts of the loop

class _Controllers:
    """The parameter controllers of the ``[[pairs]]`` and their missing-data bookkeeping."""

    def __init__(self, pairs: Sequence[_Pair], ts: float) -> None:
        self.pairs = list(pairs)
        self.names = [p.parameter for p in self.pairs]
        #: the PI pairs (the box's law, which also moves within a sample)
        self._pi = [p for p in self.pairs if isinstance(p.controller, ScaledPI)]
        self.ts = float(ts)
        #: tag -> time its measurement went missing (None while present)
        self.missing: dict[str, float | None] = {p.tag: None for p in self.pairs}
        #: time of the last update (a sample or a sub-step); None before the first
        self.last_time: float | None = None

    def _dt(self, t: float) -> float | None:
        """Time since the last update, or None when it is the sample time (or there was none)."""
        if self.last_time is None:
            return None
        dt = t - self.last_time
        return None if math.isclose(dt, self.ts, rel_tol=1e-12) else dt

    def _advance(self, p: _Pair, sp: float, pv: float, hold: bool, dt: float | None) -> None:
        if dt is not None and isinstance(p.controller, ScaledPI):
            p.controller.update(sp, pv, hold=hold, dt=dt)
        else:
            p.controller.update(sp, pv, hold=hold)

    def substep(self, t: float, w: float, k: int, y: npt.NDArray[np.float64], ridx: Mapping[str, int],
                view: MeasurementView, hold: bool) -> None:
        """Advance the controllers to *t* inside the sample ``[t_k, t_k+1]``, a fraction *w* of it.

        The setpoint is the measurement interpolated linearly between the two
        samples, as the compiled box sees it (NaN when either is missing).
        Only the PI controllers (the box's law) move within a sample; a
        sliding-mode controller steps once a sample.
        """
        dt = self._dt(t)
        samples = view.samples
        for p in self._pi:
            s = samples[p.tag]
            sp = (1.0 - w) * float(s[k]) + w * float(s[k + 1])
            p.controller.update(sp, float(y[ridx[p.fmu_name]]), hold=hold, dt=dt)
        self.last_time = t

    def values(self) -> dict[str, float]:
        """Parameter name -> the value its controller outputs."""
        return {p.parameter: p.controller.value for p in self.pairs}

    def update(self, t: float, k: int, y: npt.NDArray[np.float64], ridx: Mapping[str, int], view: MeasurementView,
               hold: bool, event: Callable[..., None]) -> list[str]:
        """Advance every controller one sample (setpoint: the measured tag); return their modes."""
        modes = []
        dt = self._dt(t)
        for p in self.pairs:
            sp = float(view.samples[p.tag][k])
            pv = float(y[ridx[p.fmu_name]])
            ok = math.isfinite(sp)
            if not ok and self.missing[p.tag] is None:
                self.missing[p.tag] = t
                event(t, "missing", f"tag {p.tag!r} missing from t = {t:g} s: controller of "
                      f"{p.parameter!r} on hold", logging.INFO)
            elif ok and self.missing[p.tag] is not None:
                event(t, "resumed", f"tag {p.tag!r} back at t = {t:g} s after {t - self.missing[p.tag]:g} s; "
                      f"controller of {p.parameter!r} resumes (bumpless)", logging.INFO)
                self.missing[p.tag] = None
            self._advance(p, sp, pv, hold, dt)
            modes.append(p.controller.mode)
        self.last_time = t
        return modes

    def state_dict(self) -> dict[str, Any]:
        return {"controllers": {p.parameter: p.controller.state_dict() for p in self.pairs},
                "missing": dict(self.missing), "last_time": self.last_time}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        for p in self.pairs:
            p.controller.load_state_dict(state["controllers"][p.parameter])
        self.missing = {k: _from_json_float(v) for k, v in state["missing"].items()}
        self.last_time = _from_json_float(state["last_time"])


class _Compensation:
    """State compensation of the ``[[states]]``: one compensator for each twin (tracked, untracked)."""

    def __init__(self, states: Sequence[_State]) -> None:
        self.states = list(states)
        self.names = [s.correction for s in self.states]

    def update(self, k: int, y: npt.NDArray[np.float64], yu: npt.NDArray[np.float64] | None,
               ridx: Mapping[str, int], view: MeasurementView) -> tuple[dict[str, float], dict[str, float]]:
        """Correction flows for the tracked twin and the untracked one (NaN without it)."""
        corr, corr_u = {}, {}
        for s in self.states:
            meas = float(view.samples[s.tag][k])
            corr[s.correction] = s.tracked.update(meas, float(y[ridx[s.variable]]))
            corr_u[s.correction] = s.untracked.update(meas, float(yu[ridx[s.variable]])) \
                if yu is not None else math.nan
        return corr, corr_u

    def state_dict(self) -> dict[str, Any]:
        return {"tracked": {s.correction: s.tracked.state_dict() for s in self.states},
                "untracked": {s.correction: s.untracked.state_dict() for s in self.states}}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        for s in self.states:
            s.tracked.load_state_dict(state["tracked"][s.correction])
            s.untracked.load_state_dict(state["untracked"][s.correction])


class _Output:
    """The streamed CSV and the summaries of the run (parameter, correction and level ranges, fits)."""

    def __init__(self, path: Path, columns: Sequence[str], parameters: Sequence[str], corrections: Sequence[str],
                 levels: Sequence[str], fitted: Sequence[str], bands: Any = None) -> None:
        self.path = path
        #: the tracked parameters' uncertainty bands (trackingbox.identify.bands.BandTracker): two more
        #: columns per pair after the row's own, computed from the row
        self.bands = bands
        self.columns = list(columns) + (list(bands.columns) if bands is not None else [])
        self.pstats = {n: _Stats() for n in parameters}
        self.cstats = {n: _Stats() for n in corrections}
        self.sstats = {n: _Stats() for n in levels}
        self.fits = {t: _Fit() for t in fitted}
        self._fh: Any = None
        self._writer: Any = None

    def open(self) -> None:
        """Start a new CSV with its header."""
        self._fh = open(self.path, "w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._fh)
        self._writer.writerow(self.columns)

    def write(self, row: Sequence[Any]) -> None:
        self._writer.writerow(row if self.bands is None else [*row, *self.bands.row(row)])

    def writerows(self, rows: Sequence[Sequence[Any]]) -> None:
        self._writer.writerows(rows if self.bands is None else [[*r, *self.bands.row(r)] for r in rows])

    def write_text(self, text: str, rows: Any = None) -> None:
        """Rows already formatted as the csv writer writes them (:func:`trackingbox.native.format_rows`);
        *rows*: the same rows as numbers (modes as flags), for the band columns."""
        if self.bands is not None:
            text = self.bands.append_text(text, rows)
        self._fh.write(text)

    def flush(self) -> None:
        if self._fh is not None:
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def state_dict(self) -> dict[str, Any]:
        """The CSV's valid length (bytes) and the summaries; flushes the CSV first."""
        self._fh.flush()
        return {"csv_bytes": self._fh.tell(),
                "bands": self.bands.state_dict() if self.bands is not None else None,
                "parameter_stats": {n: s.state() for n, s in self.pstats.items()},
                "correction_stats": {n: s.state() for n, s in self.cstats.items()},
                "state_stats": {n: s.state() for n, s in self.sstats.items()},
                "fits": {t: f.state() for t, f in self.fits.items()}}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Cut the CSV back to the saved length (rows after it are redone) and append from there."""
        with open(self.path, "r+b") as fh:
            fh.truncate(int(state["csv_bytes"]))
        for n in self.pstats:
            self.pstats[n].restore(state["parameter_stats"][n])
        for n in self.cstats:
            self.cstats[n].restore(state["correction_stats"][n])
        for n in self.sstats:
            self.sstats[n].restore(state["state_stats"][n])
        for t in self.fits:
            self.fits[t].restore(state["fits"][t])
        if self.bands is not None:
            self.bands.load_state_dict(state["bands"])
        self._fh = open(self.path, "a", newline="", encoding="utf-8")
        self._writer = csv.writer(self._fh)


# --------------------------------------------------------------------------- carrying the integrator

#: Largest change of a tracked parameter, as a fraction of its bound range, that the tracked twin's
#: integrator carries without a restart (corrections: of the compensator's gain times its level's range)
CARRY_FRACTION = 0.02


def _carry_limits(fraction: float, pairs: Sequence[_Pair], states: Sequence[Any],
                  ranges: Mapping[str, tuple[int, float, float]]) -> dict[str, float]:
    """Value name -> the largest change the tracked twin's integrator carries (see :func:`track`).

    A parameter: *fraction* of its bound range. A correction flow: *fraction*
    of its compensator's gain times the measured range of its level (1st to
    99th percentile), the correction a level error of that size asks for.
    """
    limits = {p.parameter: fraction * (p.bounds[1] - p.bounds[0]) for p in pairs}
    for s in states:
        n, lo, hi = ranges[s.tag]  # percentile_range of the level's samples
        if n >= 2:
            limits[s.correction] = fraction * abs(float(s.gain)) * float(hi - lo)
    return limits


# --------------------------------------------------------------------------- sub-steps

#: Largest within-sample loop gain the automatic choice leaves to one step per sample ...
SUBSTEP_GAIN = 0.01
#: ... and the most sub-steps it chooses.
MAX_SUBSTEPS = 8


def within_sample_gains(loop: TrackingLoop) -> dict[str, float]:
    """Per PI pair: ``kp`` times the fraction of its steady-state response the twin shows one sample after a step.

    The compiled box's controller sees the twin answer its own parameter
    moves continuously; a runtime that reads the twin once a sample sees that
    answer a sample late. How much that matters is the loop gain closed within
    a sample: the proportional gain times the part of the pair's steady-state
    gain the variable reaches within one sample time. It is measured on the
    twin from the first sample (before the run starts): one sample with the
    start values, and one per pair with its parameter moved by a tenth of its
    range towards the middle, all else equal.
    """
    assert loop.twin is not None
    pairs = [p for p in loop.controllers.pairs if isinstance(p.controller, ScaledPI)]
    if not pairs or loop.n_rows < 2:
        return {}
    tw = loop.twin
    t1 = float(loop.grid[1])
    values = {**loop.controllers.values(), **{c: 0.0 for c in loop.compensation.names}}
    names = [p.fmu_name for p in pairs]

    def answer(changed: Mapping[str, float]) -> npt.NDArray[np.float64]:
        run = tw.model.stepper(start_time=0.0, parameters={**tw.base, **values, **changed}, inputs=tw.inputs,
                               max_step=tw.max_step)
        run.step(t1)
        y = np.asarray(run.get(names), dtype=float)
        run.finish()
        return y

    y0 = answer({})
    gains = {}
    for j, p in enumerate(pairs):
        ctrl = p.controller
        lo, hi = p.bounds
        delta = 0.1 * (hi - lo) * (1.0 if ctrl.u < 50.0 else -1.0)
        dy = float(answer({p.parameter: ctrl.value + delta})[j] - y0[j])
        fraction = abs(dy) / (ctrl.scaling.span * abs(delta) / (hi - lo))
        gains[p.parameter] = ctrl.kp * fraction if math.isfinite(fraction) else 0.0
        log.info("pair %s -> %s: %.3g of the steady-state answer within one sample; within-sample loop gain %.3g",
                 p.tag, p.parameter, fraction, gains[p.parameter])
    return gains


def substeps_for(gains: Mapping[str, float]) -> int:
    """Sub-steps per sample for within-sample loop gains (:func:`within_sample_gains`)."""
    g = max(gains.values(), default=0.0)
    if g <= SUBSTEP_GAIN:
        return 1
    return min(MAX_SUBSTEPS, math.ceil(math.sqrt(g / SUBSTEP_GAIN)))


# --------------------------------------------------------------------------- the loop's fast path

#: environment variable: ``0`` keeps the tracking loop on its Python path (no :class:`_NativeRows`)
NATIVE_ROWS_ENV = "TRACKINGBOX_NATIVE_ROWS"


def _pointers(arrays: Sequence[Any], ctype: Any) -> Any:
    """A C array of the data pointers of *arrays* (None: a null pointer)."""
    ptr = ctypes.POINTER(ctype)
    return (ptr * max(len(arrays), 1))(*(a.ctypes.data_as(ptr) if a is not None else ptr() for a in arrays))


class _NativeRows:
    """The loop's rows in C: ``tbn_track_rows`` of the native stepper's library (issue 12).

    Over a batch of rows it does what :meth:`TrackingLoop._row`,
    :meth:`~TrackingLoop._step_tracked` and :meth:`_Twin.step` do (the PI
    laws with their clamped integration, the sub-steps, the state
    compensation, the CSV row's values, the summaries, both twins' sets,
    steps and reads through ``tbn_advance``), with the same arithmetic in the
    same order, so the rows are the Python path's, byte for byte. It hands
    back to the Python path at the first row that needs it (a tag going
    missing or coming back), inside a row whose twin step did not end
    normally (an event, a failure: :meth:`TrackingLoop._step_row` finishes
    that step as the Python path would have), at a checkpoint, at the batch's
    row limit and before the last row.

    Usable (:meth:`usable`) when every pair is a :class:`ScaledPI` on the
    ``"linear"`` error, both twins run on :class:`~trackingbox.native.NativeStepper`
    (or there is no untracked twin and no untracked table) and
    ``TRACKINGBOX_NATIVE_ROWS`` is not ``0``. Every batch first checks its
    twins (:meth:`NativeStepper.rows_ready <trackingbox.native.NativeStepper.rows_ready>`).
    """

    #: rows per batch at most (the row buffer)
    CAP = 512

    def __init__(self, loop: TrackingLoop) -> None:
        from .. import native

        self.native = native
        self.lib = native.library()
        self.b = native.TrackBatch()
        self.view: Any = None
        ctl, comp, plan = loop.controllers, loop.compensation, loop.plan
        self.npairs, self.nstates = len(ctl.pairs), len(comp.states)
        self.names = [list(ctl.names) + list(comp.names), list(comp.names)]
        ridx = loop.ridx
        self.pidx = (ctypes.c_size_t * max(self.npairs, 1))(*(ridx[p.fmu_name] for p in ctl.pairs))
        self.sidx = (ctypes.c_size_t * max(self.nstates, 1))(*(ridx[s.variable] for s in comp.states))
        self.tidx = (ctypes.c_size_t * max(len(plan.out_tags), 1))(*(ridx[plan.tag_var[t]] for t in plan.out_tags))
        self.ncols = len(plan.columns)
        self.rows = np.zeros((self.CAP, self.ncols))
        self.mode_cols = list(range(self.ncols - self.npairs, self.ncols))
        self.pi = np.zeros((max(self.npairs, 1), len(native.PI_FIELDS)))
        self.comp = np.zeros((2, max(self.nstates, 1), len(native.SC_FIELDS)))
        self.fits = np.zeros((max(len(plan.out_tags), 1), 7))
        self.stats = [np.zeros((max(n, 1), 3)) for n in (self.npairs, self.nstates, self.nstates)]
        self.missing = np.zeros(max(self.npairs, 1), dtype=np.intc)
        self.io: list[dict[str, Any]] = []
        b = self.b
        b.substeps, b.ts = loop.substeps, loop.ts
        b.hold_until = loop.hold_until
        b.npairs, b.nstates, b.ntags, b.nread = self.npairs, self.nstates, len(plan.out_tags), len(loop.read)
        b.pidx, b.sidx, b.tidx = self.pidx, self.sidx, self.tidx
        b.pi = self.pi.ctypes.data_as(native._pd)
        b.comp_t = self.comp[0].ctypes.data_as(native._pd)
        b.comp_u = self.comp[1].ctypes.data_as(native._pd)
        b.fits = self.fits.ctypes.data_as(native._pd)
        b.pstats, b.cstats, b.sstats = (a.ctypes.data_as(native._pd) for a in self.stats)
        b.missing = self.missing.ctypes.data_as(native._pint)
        b.rows, b.ncols, b.cap = self.rows.ctypes.data_as(native._pd), self.ncols, self.CAP
        for which in (0, 1):
            nv = len(self.names[which])
            io = {"applied": np.zeros(max(nv, 1)), "given": np.zeros(max(nv, 1)),
                  "given_ok": np.zeros(max(nv, 1), dtype=np.intc), "ever_set": np.zeros(max(nv, 1), dtype=np.intc),
                  "limit": np.full(max(nv, 1), math.nan), "extrap": np.zeros(max(nv, 1), dtype=np.intc),
                  "lo": np.zeros(max(nv, 1)), "hi": np.zeros(max(nv, 1)), "y": np.zeros(max(len(loop.read), 1)),
                  "val": np.zeros(max(nv, 1)), "sub": np.zeros(max(nv, 1)),
                  "sub_vr": (ctypes.c_uint32 * max(nv, 1))(), "sub_idx": (ctypes.c_size_t * max(nv, 1))()}
            t = b.tw[which]
            t.nv = nv
            for name in ("applied", "given", "limit", "lo", "hi", "y", "val", "sub"):
                setattr(t, name, io[name].ctypes.data_as(native._pd))
            for name in ("given_ok", "ever_set", "extrap"):
                setattr(t, name, io[name].ctypes.data_as(native._pint))
            t.sub_vr, t.sub_idx = io["sub_vr"], io["sub_idx"]
            self.io.append(io)

    @staticmethod
    def usable(loop: TrackingLoop) -> bool:
        """True if the loop's rows can run in C (see the class docstring)."""
        import os

        if os.environ.get(NATIVE_ROWS_ENV, "").strip() == "0" or loop.interpolation != "linear":
            return False
        if not all(isinstance(p.controller, ScaledPI) for p in loop.controllers.pairs):
            return False
        native = _native_stepper()
        if not isinstance(loop.twin.stepper if loop.twin is not None else None, native):
            return False
        if loop.plain is None:
            return loop.plan.untracked_table is None
        return isinstance(loop.plain.stepper, native)

    def _set_view(self, loop: TrackingLoop) -> None:
        """The measurement view's arrays (again after :meth:`TrackingLoop.extend`)."""
        view, plan, b = loop.view, loop.plan, self.b
        fits = loop.output.fits
        self.grid = np.ascontiguousarray(view.grid, dtype=float)
        self.stopped = np.ascontiguousarray(view.stopped, dtype=np.uint8)
        samples = {t: np.ascontiguousarray(view.samples[t], dtype=float) for t in
                   {*(p.tag for p in loop.controllers.pairs), *(s.tag for s in loop.compensation.states),
                    *plan.out_tags}}
        self.samples = samples
        self.scored = [np.ascontiguousarray(view.scored[t], dtype=np.uint8) if t in fits else None
                       for t in plan.out_tags]
        b.grid = self.grid.ctypes.data_as(self.native._pd)
        b.stopped = self.stopped.ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte))
        self.psamples = _pointers([samples[p.tag] for p in loop.controllers.pairs], ctypes.c_double)
        self.ssamples = _pointers([samples[s.tag] for s in loop.compensation.states], ctypes.c_double)
        self.tsamples = _pointers([samples[t] for t in plan.out_tags], ctypes.c_double)
        self.pscored = _pointers(self.scored, ctypes.c_ubyte)
        b.psamples, b.ssamples, b.tsamples, b.scored = self.psamples, self.ssamples, self.tsamples, self.pscored
        self.view = view

    # ------------------------------------------------------------------ state to C and back

    def _twin_in(self, which: int, tw: _Twin | None, read: list[str]) -> bool:
        """The twin's state into ``tw[which]``; False if its stepper cannot take a batch now."""
        t = self.b.tw[which]
        if tw is None:
            t.h = None
            return True
        st = tw.stepper
        names = self.names[which]
        if not tw.me or tw.read_names is None or any(n not in tw.applied for n in names):
            return False
        ready = st.rows_ready([tw.fmu_name(n) for n in names], read)
        if ready is None:
            return False
        out, vrs, is_param = ready
        io = self.io[which]
        nv = len(names)
        io["vr"] = (ctypes.c_uint32 * max(nv, 1))(*vrs)
        io["is_param"] = (ctypes.c_int * max(nv, 1))(*is_param)
        t.vr, t.is_param = io["vr"], io["is_param"]
        t.out = out.ctypes.data_as(self.native._pd)
        io["out"] = out
        for i, n in enumerate(names):
            io["applied"][i] = tw.applied[n]
            g = tw.given.get(n)
            io["given_ok"][i] = g is not None
            io["given"][i] = g if g is not None else 0.0
            io["limit"][i] = tw.carry_limits.get(n, math.nan)
            bounds = tw.extrapolate.get(n)
            io["extrap"][i] = bounds is not None
            if bounds is not None:
                io["lo"][i], io["hi"][i] = bounds
        io["ever_set"][:] = 0
        t.carry_any = 1 if tw.carry_limits else 0
        t.force_restart = 1 if tw.force_restart else 0
        t.exact = 1 if st._solver.exact else 0
        t.time = st.time
        t.carried = t.restarts = 0
        t.seconds = 0.0
        y = tw.y if tw.y is not None else st.get(read)
        io["y"][: len(read)] = y
        io["time0"] = st.time
        t.h = st._handle
        return True

    def _twin_out(self, which: int, tw: _Twin | None) -> None:
        """``tw[which]``'s state back into the twin and its stepper."""
        if tw is None:
            return
        t, io, st = self.b.tw[which], self.io[which], tw.stepper
        names = self.names[which]
        applied, given = io["applied"].tolist(), io["given"].tolist()
        for i, n in enumerate(names):
            tw.applied[n] = applied[i]
        if names and io["given_ok"][0]:
            tw.given = {n: given[i] for i, n in enumerate(names)}
        tw.force_restart = bool(t.force_restart)
        tw.step_seconds += t.seconds
        moved = t.time != io["time0"]
        st.rows_done(t.time, t.carried, t.restarts,
                     {tw.fmu_name(n): applied[i] for i, n in enumerate(names) if io["ever_set"][i]})
        if moved:
            tw.x = st._x[: st._nx].copy()
            tw.x_time = float(t.time)
            tw.y = io["y"][: self.b.nread].copy()

    def _state_in(self, loop: TrackingLoop) -> None:
        for i, p in enumerate(loop.controllers.pairs):
            c = p.controller
            sc = c.scaling
            self.pi[i] = (c.u, c.e_mem if c.e_mem is not None else 0.0, c.e_mem is not None,
                          c.e_last if c.e_last is not None else 0.0, c.e_last is not None, c.hold_last,
                          c.direction * c.kp, c.ti, c.te, sc.span, sc.p_min, sc.p_max, c.mode == "hold")
            self.missing[i] = loop.controllers.missing[p.tag] is not None
        for i, s in enumerate(loop.compensation.states):
            for j, c in enumerate((s.tracked, s.untracked)):
                self.comp[j, i] = (c.m, c.e_mem if c.e_mem is not None else 0.0, c.e_mem is not None,
                                   c.e_last if c.e_last is not None else 0.0, c.e_last is not None, c.hold_last,
                                   c.gain, c.ts, c.te, c.mode == "hold")
        out = loop.output
        for i, tag in enumerate(loop.plan.out_tags):
            fit = out.fits.get(tag)
            if fit is not None:
                self.fits[i] = fit.state()
        for arr, stats in zip(self.stats, (out.pstats, out.cstats, out.sstats)):
            for i, st in enumerate(stats.values()):
                arr[i] = st.state()
        b = self.b
        b.hold_k = 1 if loop.hold_k else 0
        last = loop.controllers.last_time
        b.has_last_time = last is not None
        b.last_time = last if last is not None else 0.0
        b.recovery_until = loop.recovery_until

    def _state_out(self, loop: TrackingLoop) -> None:
        def memory(row: Any, c: Any) -> None:
            c.e_mem = row[1] if row[2] else None
            c.e_last = row[3] if row[4] else None
            c.hold_last = bool(row[5])
            c.mode = "hold" if row[-1] else "auto"

        for p, row in zip(loop.controllers.pairs, self.pi.tolist()):
            p.controller.u = row[0]
            memory(row, p.controller)
        for i, s in enumerate(loop.compensation.states):
            for j, c in enumerate((s.tracked, s.untracked)):
                row = self.comp[j, i].tolist()
                c.m = row[0]
                memory(row, c)
        out = loop.output
        for i, tag in enumerate(loop.plan.out_tags):
            fit = out.fits.get(tag)
            if fit is not None:
                fit.restore(self.fits[i].tolist())
        for arr, stats in zip(self.stats, (out.pstats, out.cstats, out.sstats)):
            for i, st in enumerate(stats.values()):
                st.restore(arr[i].tolist())
        b = self.b
        loop.hold_k = bool(b.hold_k)
        if b.has_last_time:
            loop.controllers.last_time = b.last_time

    # ------------------------------------------------------------------ a batch

    def _rows(self, loop: TrackingLoop) -> None:
        """The C call of a batch (its state is in :attr:`b`)."""
        self.lib.tbn_track_rows(ctypes.byref(self.b))

    def run(self, loop: TrackingLoop, k: int, k_stop: int
            ) -> tuple[int, tuple[dict[str, float], dict[str, float], tuple[int, int, int]] | None, bool]:
        """Rows *k* .. at most *k_stop* - 1 in C: ``(rows written, pending, python)``.

        :attr:`TrackingLoop.k` moves past the rows that were written and
        stepped. *pending*: the last row written was not stepped to its end:
        ``(values, corrections of the untracked twin, (twin, sub-step, code))``
        for :meth:`TrackingLoop._step_row`. *python*: the row at
        :attr:`TrackingLoop.k` needs the Python path.
        """
        if self.view is not loop.view:
            self._set_view(loop)
        read = loop.read
        if not (self._twin_in(0, loop.twin, read) and self._twin_in(1, loop.plain, read)):
            return 0, None, True
        self._state_in(loop)
        b = self.b
        b.k0, b.k_stop = k - loop.off, k_stop - loop.off  # rows of the current window
        self._rows(loop)
        self._twin_out(0, loop.twin)
        self._twin_out(1, loop.plain)
        self._state_out(loop)
        done = int(b.done)
        interrupted = b.status == self.native.ROWS_INTERRUPTED
        written = done + (1 if interrupted else 0)
        if written:
            text = self.native.format_rows(self.rows[:written], self.npairs)
            if text is not None:
                loop.output.write_text(text, self.rows[:written])
            else:
                rows = self.rows[:written].tolist()
                for row in rows:
                    for c in self.mode_cols:
                        row[c] = "hold" if row[c] else "auto"
                loop.output.writerows(rows)
        loop.k = k + done
        pending = None
        if interrupted:
            row = self.rows[written - 1].tolist()
            np_, ns = self.npairs, self.nstates
            first = self.ncols - np_ - 2 * ns - np_
            params = row[first: first + np_]
            corr = row[first + np_: first + np_ + ns]
            corr_u = row[first + np_ + ns: first + np_ + 2 * ns]
            names = self.names[0]
            values = dict(zip(names, params + corr))
            pending = (values, dict(zip(self.names[1], corr_u)), (int(b.which), int(b.sub), int(b.code)))
        return written, pending, b.status == self.native.ROWS_PYTHON


#: Nominal values of the controllers' states in the continuous mode, as a multiple of their range:
#: a PI controller's output and error memory get ``CLOSED_RANGE_FACTOR * 100 %`` (the output's full
#: range), a compensator's error memory the factor times its level's measured range and its
#: correction the factor times the gain times that range; their absolute tolerance is the twin's
#: rtol times these. Measured against the same mode at rtol 1e-10 (rtol 1e-6): heat exchanger (3 h)
#: factor 1 gives 6.8e-6 of the parameter's range and 1.2e-5 / 4.5e-5 of the tags' ranges at 1.7x
#: the integrator CPU of factor 10, which gives 4.3e-5 and 4.2e-5 / 6.8e-5 (the discrete path: 2.4e-4
#: and 2.1e-4 / 3.5e-4 from the same reference); factor 100 went to 5.1e-4 of the parameter's range
#: (without stops at the samples). Heat production (2 h, three pairs, three levels): factor 10 on the
#: compensators too takes 30 % less integrator CPU than 1 and keeps every tag, parameter and
#: correction within 6.1e-5 of its range (LI-400; factor 1: 1e-5).
CLOSED_RANGE_FACTOR = 10.0


class _ClosedRows(_NativeRows):
    """The loop's rows with the controllers inside the integrated system: ``tbn_closed_rows`` (issue 12).

    Each pair's PI law (:class:`~trackingbox.tracking.controllers.ScaledPI`'s
    continuous form, the compiled box's ``Blocks.ParameterController``) and
    each level's compensator (``Blocks.StateCompensation``) are continuous
    states that CVODE integrates with the twin's states in one right-hand side,
    which reads the measurement interpolated linearly between samples and
    sets the parameters and corrections as the twin's Real *inputs*. The
    untracked twin runs the same way with its compensators. CVODE stops at
    every sample (its stop time, where the interpolated data have their kinks;
    no re-initialisation) and is re-initialised only at the start of a batch
    (a checkpoint, the row buffer's end) and where a hold starts or ends or a
    tag goes missing or comes back. Between batches the controllers are
    handed to and from their discrete form (``u``, the error memory), so a row
    that needs Python (a tag going missing or coming back, a solver failure)
    runs on the discrete path and the next batch goes on from it.
    """

    def __init__(self, loop: TrackingLoop) -> None:
        super().__init__(loop)
        ctl, comp = loop.controllers, loop.compensation
        tw = loop.twin
        assert tw is not None
        self.set_names = [[tw.fmu_name(n) for n in ctl.names] + list(comp.names), list(comp.names)]
        self.sim_names = [[p.fmu_name for p in ctl.pairs] + [s.variable for s in comp.states],
                          [s.variable for s in comp.states]]
        level_nominal = []
        for s_ in comp.states:
            n, lo, hi = loop.ranges[s_.tag]
            rng = float(hi - lo) if n >= 2 else 0.0
            rng = CLOSED_RANGE_FACTOR * (rng if rng > 0.0 else 1.0)
            level_nominal += [rng, max(abs(float(s_.tracked.gain)) * rng, 1e-12)]
        #: nominal values of the controllers' states (absolute tolerance: the twin's rtol times these),
        #: see :data:`CLOSED_RANGE_FACTOR`
        pi_nominal = CLOSED_RANGE_FACTOR * 100.0
        self.nominal = [[pi_nominal, pi_nominal] * len(ctl.pairs) + level_nominal, level_nominal]

    def _rows(self, loop: TrackingLoop) -> None:
        handles = []
        for which, tw in enumerate((loop.twin, loop.plain)):
            if tw is None:
                handles.append(None)
                continue
            handles.append(tw.stepper.closed(len(loop.controllers.pairs) if which == 0 else 0,
                                             self.set_names[which], self.sim_names[which], self.nominal[which]))
        self.lib.tbn_closed_rows(ctypes.byref(self.b), self.grid.size, handles[0], handles[1])
        for io in self.io:
            io["ever_set"][:] = 1  # the inputs hold the values at the twin's time

    def _state_out(self, loop: TrackingLoop) -> None:
        super()._state_out(loop)
        loop.controllers.last_time = None  # nothing is left to integrate up to the twin's time


# --------------------------------------------------------------------------- the loop

class TrackingLoop:
    """The tracking loop over a spec's measurement view, made of parts that save their own state.

    Parts: the parameter controllers, the state compensation, the tracked twin,
    the untracked twin (optional) and the output stream (CSV and summaries).
    Each has ``state_dict()`` / ``load_state_dict()``; :meth:`state_dict` of
    the loop is theirs plus the loop's own (row, recovery hold, events) and is
    what ``checkpoint.json`` holds. Use it through :func:`track`, or::

        loop = TrackingLoop(spec, out_dir=out)
        try:
            loop.begin(resume=False)
            loop.run()
        finally:
            loop.close()
        result = loop.result()

    Parameters are those of :func:`track`.
    """

    def __init__(self, spec: Spec, *, out_dir: str | Path, window: Window = "all",
                 untracked: bool | pd.DataFrame = True, checkpoint_every: int = 200,
                 recovery_hold: float | None = None, tolerance: float = 1e-6,
                 view: MeasurementView | None = None, interpolation: Interpolation = "linear",
                 substeps: int | Literal["auto"] = "auto", carry: float = CARRY_FRACTION,
                 controllers: ControllerMode = "discrete", inputs_twin: Any = None,
                 window_rows: int | None = None) -> None:
        from ..spec import check_against_fmu

        self.wall0 = _time.perf_counter()
        self.spec = spec
        self.window = window
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.csv_path = self.out_dir / CSV_NAME
        self.ckpt_path = self.out_dir / CHECKPOINT_NAME
        self.checkpoint_every = int(checkpoint_every)
        self._ckpt = CheckpointFile(self.ckpt_path, self.csv_path)
        check_against_fmu(spec)
        #: the run's measurements window by window (:mod:`trackingbox.stream`); None: the whole view
        #: (given, or where windows are not exact), with :attr:`view` that view
        self.stream: WindowedMeasurements | None = None
        rows = WINDOW_ROWS if window_rows is None else int(window_rows)
        if rows > 0 and controllers == "continuous":  # a window holds a whole batch (see _window_for)
            rows = max(rows, _NativeRows.CAP + MARGIN_ROWS + 2)
        stat_tags = list(dict.fromkeys([*(p.variable for p in spec.pairs if p.variable in spec.outputs),
                                        *(s.tag for s in spec.states)]))
        if view is None and rows > 0 and spec.pairs and not isinstance(untracked, pd.DataFrame):
            self.stream = WindowedMeasurements.open(spec, window, skip=float(spec.tracking.hold_until),
                                                    directory=self.out_dir, stats_tags=stat_tags,
                                                    rows_per_window=rows)
            if self.stream is not None:
                if all(self.stream.input_missing[t] < self.stream.n_rows for t in spec.inputs):
                    view = self.stream.view(0, min(self.stream.n_rows, rows + MARGIN_ROWS))
                else:  # an input with no value: the whole view's checks word it
                    self.stream.close()
                    self.stream = None
        try:
            self.plan = plan = _plan(spec, window, untracked, view, self.stream)
        except BaseException:
            if self.stream is not None:
                self.stream.close()
            raise
        #: the current window (the whole view without :attr:`stream`) and the row of the run its first row is
        self.view = plan.view
        self.off = 0
        self.grid: Any = self.stream.grid if self.stream is not None else plan.view.grid
        self.n_rows = int(self.grid.size)
        #: tag -> (valid samples, 1st, 99th percentile) over the run, of each pair's variable and each level
        self.ranges = {tag: self.stream.percentiles(tag) if self.stream is not None
                       else percentile_range(self.view.samples[tag]) for tag in stat_tags}
        #: the twins' steppers run (their input tables follow the windows)
        self._running = False
        self.ts = ts = float(spec.sample_time)
        self.hold_until = float(spec.tracking.hold_until)
        self.recovery_hold = 10.0 * ts if recovery_hold is None else float(recovery_hold)
        self.events = plan.events

        if interpolation not in ("zoh", "linear"):
            raise ValueError(f"interpolation must be 'zoh' or 'linear', got {interpolation!r}")
        if controllers not in ("discrete", "continuous"):
            raise ValueError(f"controllers must be 'discrete' or 'continuous', got {controllers!r}")
        self.mode: ControllerMode = controllers
        continuous = controllers == "continuous"
        if continuous:
            if interpolation != "linear":
                raise ValueError("controllers='continuous' integrates the box's law on the interpolated "
                                 f"measurement: it needs interpolation='linear', not {interpolation!r}")
            if substeps not in ("auto", 1):
                raise ValueError(f"controllers='continuous' integrates the controllers with the twin: there are "
                                 f"no sub-steps to choose (got substeps={substeps!r})")
            if any(getattr(p, "controller", "pi") != "pi" for p in spec.pairs):
                raise SpecError(f"controllers='continuous' runs PI pairs only; {spec.path} has a sliding-mode pair")
            if inputs_twin is None:
                from ..generate.inputs_twin import inputs_twin as make_inputs_twin

                inputs_twin = make_inputs_twin(spec)
        #: the twin with its tracked parameters as inputs (continuous mode), else None
        self.inputs_twin = inputs_twin
        self.interpolation = interpolation
        pairs = [_make_controller(spec, p, self.view.samples[p.variable], interpolation) for p in spec.pairs]
        for p in pairs:
            _check_authority(p, self.ranges[p.tag], self.events)
        self.controllers = _Controllers(pairs, ts)
        self.compensation = _Compensation([
            _State(s.tag, s.variable, s.correction, StateCompensator(s.gain, ts=ts, interpolation=interpolation),
                   StateCompensator(s.gain, ts=ts, interpolation=interpolation))
            for s in spec.states])
        from ..identify.hooks import band_tracker  # the tracked parameters' bands: two columns per pair

        self.output = _Output(self.csv_path, plan.columns, self.controllers.names, self.compensation.names,
                              [s.tag for s in spec.states], list(spec.outputs), band_tracker(spec, plan.columns))
        self.read = plan.read_names
        self.ridx = {name: i for i, name in enumerate(self.read)}
        #: the view the row plan was made for, and per output tag: (read index, samples, scored or None, fit)
        self._columns: tuple[Any, list[tuple[int, Any, Any, Any]]] = (None, [])
        self.recovery_until = -math.inf
        self.k = 0
        self.k0 = 0
        self.complete = True
        base = {p.name: p.start for p in spec.parameters}
        base.update(spec.fixed)
        recorded = {**{n: f"parameter:{n}" for n in self.controllers.names},
                    **{n: f"correction:{n}" for n in self.compensation.names}}
        self.twin: _Twin | None = None
        self.plain: _Twin | None = None
        extrapolate = {p.parameter: p.bounds for p in pairs if isinstance(p.controller, ScaledPI)} \
            if interpolation == "linear" and not continuous else {}
        self.twin = _Twin(inputs_twin.fmu if continuous else spec.twin, label="tracked", base=base,
                          inputs=self.view.inputs, tolerance=tolerance, recorded=recorded, extrapolate=extrapolate,
                          rename=inputs_twin.inputs if continuous else None)
        if untracked is True:
            try:
                self.plain = _Twin(spec.twin, label="untracked", base=base, inputs=self.view.inputs,
                                   tolerance=tolerance,
                                   recorded={n: f"untracked_correction:{n}" for n in self.compensation.names})
            except BaseException:
                self.twin.close()
                raise
        for tw in (self.twin, self.plain):
            if tw is not None:
                tw.read_names, tw._read_key = self.read, tuple(self.read)
                if self.stream is not None:
                    tw.max_step, tw.replay_inputs = self.stream.max_step, self._replay_inputs
        if not (isinstance(carry, (int, float)) and math.isfinite(carry) and carry >= 0.0):
            raise ValueError(f"carry must be a finite fraction >= 0, got {carry!r}")
        self.carry = float(carry)
        if self.carry > 0.0 and self.twin.me and not continuous:
            self.twin.carry_limits = _carry_limits(self.carry, pairs, spec.states, self.ranges)
        #: hold flag of the current sample (given at its start, used by its sub-steps)
        self.hold_k = True
        #: the rows in C (:class:`_NativeRows`), made on first use where usable
        self._fast: _NativeRows | None = None
        self._fast_checked = False
        #: rows this loop ran in C (its :meth:`run` calls)
        self.native_rows = 0
        self.substeps = 1 if continuous else self._substeps(substeps, interpolation)

    def _substeps(self, substeps: int | Literal["auto"], interpolation: Interpolation) -> int:
        """Sub-steps per sample: the given number, or the automatic choice (see :func:`track`)."""
        assert self.twin is not None
        if substeps == "auto":
            if interpolation != "linear" or not self.twin.me:
                return 1
            try:
                gains = within_sample_gains(self)
            except SimulationError as exc:
                log.warning("the twin failed in the one-sample probe that chooses the sub-steps (%s); "
                            "one step per sample", exc)
                return 1
            return substeps_for(gains)
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
            raise ValueError(f"substeps must be a positive integer or 'auto', got {substeps!r}")
        n = int(substeps)
        if n > 1 and interpolation != "linear":
            raise ValueError("sub-steps integrate the controllers with the twin for an interpolated error: "
                             f"they need interpolation='linear', not {interpolation!r}")
        if n > 1 and not self.twin.me:
            raise ValueError(f"sub-steps need a model-exchange twin (its states restart a resumed run); "
                             f"{self.spec.twin} is co-simulation only")
        return n

    def _native_rows(self) -> _NativeRows | None:
        """The fast path for the next rows (made on first use), or None where the rows run in Python."""
        fast = self._fast
        if fast is None:
            if self._fast_checked or not _NativeRows.usable(self):
                self._fast_checked = True
                return None
            fast = self._fast = _ClosedRows(self) if self.mode == "continuous" else _NativeRows(self)
        elif not _NativeRows.usable(self):  # the untracked twin was dropped, a twin restarted on the Python path
            return None
        return fast

    # ------------------------------------------------------------------ windows

    def _limit(self) -> int:
        """Rows below this run in the current window: it reaches :data:`MARGIN_ROWS` past them, or to the end."""
        end = self.off + int(self.view.grid.size)
        return end if end >= self.n_rows else end - MARGIN_ROWS

    def _window_for(self, k: int, stop: int | None = None) -> None:
        """Make the current window hold rows *k* .. *stop* - 1 (default: row *k*) to run (a windowed run).

        Else the next window starts at the row before *k*, and the twins' tables with it: a running
        stepper goes on with the new table (:meth:`~trackingbox.fmu.Stepper.replace_inputs`), which
        holds the same rows from the one before *k* to :data:`MARGIN_ROWS` past the window's last row
        run; the solver does not look further than one step (one sample) past a row. A batch of rows
        in C (*stop*: where it would end anyway, at a checkpoint or its row buffer's end) is not cut
        by a window: the continuous mode re-initialises its integrator at every batch.
        """
        stream = self.stream
        if stream is None:
            return
        k = min(max(int(k), 0), self.n_rows - 1)
        stop = k + 1 if stop is None else max(int(stop), k + 1)
        if self.off <= k and stop <= self._limit():
            return
        a = max(0, k - 1)
        view = stream.view(a, min(self.n_rows, a + stream.rows_per_window + MARGIN_ROWS))
        self.plan.view = self.view = view
        self.off = a
        for tw in (self.twin, self.plain):
            if tw is None:
                continue
            tw.inputs = view.inputs
            if self._running and tw.stepper is not None:
                tw.stepper.replace_inputs(view.inputs)

    def _replay_inputs(self, rows: int) -> pd.DataFrame:
        """The twins' input table from row 0 past row *rows* (a replay of a windowed run from the start)."""
        assert self.stream is not None
        return self.stream.view(0, min(self.n_rows, rows + 1 + MARGIN_ROWS)).inputs

    # ------------------------------------------------------------------ state

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue the run from row :attr:`k` (JSON-serialisable after ``_jsonify``)."""
        assert self.twin is not None
        rows = self.k
        return {
            "version": _CHECKPOINT_VERSION,
            "spec": str(self.spec.path),
            "sample_time": self.ts,
            "columns": self.plan.columns,
            "rows": rows,
            "rows_total": self.n_rows,
            "window": self.window,
            "interpolation": self.interpolation,
            "substeps": self.substeps,
            "carry": self.carry,
            "controllers_mode": self.mode,
            "time": float(self.grid[min(rows, self.n_rows - 1)]),
            "complete": rows >= self.n_rows,
            "parameters": self.controllers.values(),
            "loop": {"recovery_until": self.recovery_until, "hold": self.hold_k,
                     "events": [[e.time, e.kind, e.message] for e in self.events]},
            "controllers": self.controllers.state_dict(),
            "compensation": self.compensation.state_dict(),
            "twin": self.twin.state_dict(),
            "untracked_twin": self.plain.state_dict() if self.plain is not None else None,
            "output": self.output.state_dict(),
        }

    def check_state(self, state: Mapping[str, Any]) -> None:
        """:class:`SpecError` unless *state* was saved by a run of this spec, version and window."""
        if state.get("version") != _CHECKPOINT_VERSION or state.get("columns") != self.plan.columns \
                or not math.isclose(float(state.get("sample_time", -1)), self.ts):
            raise SpecError(f"checkpoint {self.ckpt_path} was written for a different spec or version; "
                            "run without --resume to start over")
        if state.get("controllers_mode") != self.mode:
            raise SpecError(f"checkpoint {self.ckpt_path} was written with controllers="
                            f"{state.get('controllers_mode')!r}, not {self.mode!r}; resume with the same mode or "
                            "run without --resume")
        if state.get("substeps") != self.substeps:
            raise SpecError(f"checkpoint {self.ckpt_path} was written with {state.get('substeps')} sub-steps per "
                            f"sample, not {self.substeps}; resume with substeps={state.get('substeps')} or run "
                            "without --resume")
        if state.get("carry") != self.carry:
            raise SpecError(f"checkpoint {self.ckpt_path} was written with carry={state.get('carry')!r}, not "
                            f"{self.carry!r}; resume with the same carry or run without --resume")
        if state.get("interpolation") != self.interpolation:
            raise SpecError(f"checkpoint {self.ckpt_path} was written with interpolation "
                            f"{state.get('interpolation')!r}, not {self.interpolation!r}; run without --resume")
        if state.get("window") != self.window or int(state.get("rows_total", -1)) != self.n_rows:
            raise SpecError(f"checkpoint {self.ckpt_path} was written for window {state.get('window')!r} "
                            f"({state.get('rows_total')} rows), not {self.window!r} ({self.n_rows} rows); resume "
                            f"with --window {state.get('window')} or run without --resume")

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Continue from a saved state: each part restores its own; the twins from states or a replay."""
        assert self.twin is not None
        self.check_state(state)
        self.k = self.k0 = int(state["rows"])
        self.output.load_state_dict(state["output"])
        self.controllers.load_state_dict(state["controllers"])
        self.compensation.load_state_dict(state["compensation"])
        self.recovery_until = float(state["loop"]["recovery_until"])
        self.hold_k = bool(state["loop"]["hold"])
        for e in state["loop"].get("events", []):
            self.events.append(TrackingEvent(float(e[0]), str(e[1]), str(e[2])))
        t_k = float(self.grid[self.k0]) if self.k0 < self.n_rows else float(self.grid[-1])
        self._window_for(self.k0)
        self.twin.load_state_dict(state["twin"], t=t_k, csv_path=self.csv_path, rows=self.k0, grid=self.grid,
                                  substeps=self.substeps)
        if self.plain is not None:
            self.plain.load_state_dict(state["untracked_twin"] or {"x": None}, t=t_k, csv_path=self.csv_path,
                                       rows=self.k0, grid=self.grid)
        self._running = True
        log.info("resumed at row %d (t = %g s) from %s", self.k0, t_k, self.ckpt_path)

    # ------------------------------------------------------------------ running

    def begin(self, *, resume: bool = False) -> None:
        """Start fresh, or from ``checkpoint.json`` when *resume* and there is one."""
        assert self.twin is not None
        self._begin(resume)
        if self.mode == "continuous" and not _ClosedRows.usable(self):
            reason = self.twin.model.native_reason or (
                f"{NATIVE_ROWS_ENV}=0" if os.environ.get(NATIVE_ROWS_ENV, "").strip() == "0"
                else "the twins do not run on the native stepper")
            raise SimulationError(f"controllers='continuous' integrates the controllers in the native stepper's "
                                  f"right-hand side, which is not to be had here: {reason}")

    def _begin(self, resume: bool) -> None:
        assert self.twin is not None
        if resume and self.ckpt_path.exists():
            # sealed: a corrupt or truncated checkpoint, or a CSV that is not the one it vouches for, is refused
            self.load_state_dict(_unjsonify(self._ckpt.read()))
            return
        if resume:
            log.info("no checkpoint in %s; starting from the beginning", self.out_dir)
        corrections = {c: 0.0 for c in self.compensation.names}
        self.twin.start(0.0, {**self.controllers.values(), **corrections})
        if self.plain is not None:
            self.plain.start(0.0, dict(corrections))
        self._running = True
        self.output.open()

    def extend(self, view: MeasurementView) -> None:
        """Go on over a longer measurement view: data that arrived while the loop ran (the online mode).

        *view* must have the current grid as its prefix (same start and
        ``sample_time``; built as in :func:`track`). The rows still to run read
        their samples from it, and the twins restart at the current row from
        their states (or a replay), as at a checkpoint, with *view*'s longer
        input table. Drive the loop sample by sample with ``extend`` then
        ``run(max_steps=...)`` over the rows whose next sample has arrived.
        """
        if self.stream is not None:
            raise DataError("extend() goes on over a longer measurement view: start the loop with view= "
                            "(the whole view), not from the spec's file window by window")
        n = self.n_rows
        if view.grid.size < n or not np.array_equal(view.grid[:n], self.grid) or view.skip != self.view.skip:
            raise DataError(f"the measurement view given to extend() does not continue the grid of "
                            f"{self.view.source.name} ({n} rows of {self.ts:g} s from 0)")
        self.output.flush()
        self.plan.view = self.view = view
        self.grid, self.n_rows = view.grid, view.grid.size
        t_k = float(self.grid[min(self.k, self.n_rows - 1)])
        for tw in (self.twin, self.plain):
            if tw is None:
                continue
            tw.inputs = view.inputs
            if tw.me and tw.x is not None and math.isclose(tw.x_time, t_k, abs_tol=1e-9 * max(1.0, t_k)):
                if tw.carry_limits and tw.stepper is not None and tw.stepper.time == tw.x_time:
                    # its integrator stopped at t_k and never saw past the old table: it goes on
                    # (carried), so the run is the one an offline run over the whole view makes
                    tw.stepper.extend_inputs(view.inputs)
                else:
                    tw.start(t_k, dict(tw.applied), tw.x)
            else:
                tw.replay_csv(self.csv_path, self.k, self.grid)

    def checkpoint(self) -> None:
        """Write :meth:`state_dict` to ``checkpoint.json``, atomically."""
        self._ckpt.write(_jsonify(self.state_dict()))

    def event(self, t: float, kind: str, message: str, level: int = logging.WARNING) -> None:
        log.log(level, "t = %g s: %s", t, message)
        if len(self.events) < 1000:
            self.events.append(TrackingEvent(float(t), kind, message))

    def _step_tracked(self, k: int, values: dict[str, float], resume: tuple[int, int] | None = None) -> bool:
        """Step the tracked twin from row k to k+1, with the controllers on it at every sub-step.

        With :attr:`substeps` ``n > 1`` the sample is cut into ``n`` equal
        parts; after each (but the last, which row k+1 takes) the controllers
        read the twin and advance with the measurement interpolated, and the
        twin gets their new values: the box's continuous loop, sampled ``n``
        times finer. True if the twin had to recover from a solver failure
        (the controllers then stay as they are for the rest of the sample).

        *resume* ``(j, code)``: a batch of rows (:class:`_NativeRows`) stepped
        the sub-steps before ``j`` and the ``tbn_advance`` of sub-step ``j``
        returned *code*; go on from there.
        """
        assert self.twin is not None
        n = self.substeps
        j0, code = resume if resume is not None else (1, None)
        if n == 1:
            return self._safe_step(self.twin, k, values, code=code)
        t_k, t_next = float(self.grid[k]), float(self.grid[k + 1])
        h = (t_next - t_k) / n
        t_from = t_k if j0 == 1 else t_k + (j0 - 1) * h
        if j0 > 1:
            values = {**values, **self.controllers.values()}
        recovered = False
        for j in range(j0, n + 1):
            t_to = t_next if j == n else t_k + j * h
            recovered = self._safe_step(self.twin, k, values, t_from, t_to, code=code) or recovered
            code = None
            t_from = t_to
            if j < n and not recovered:
                y = self.twin.get(self.read)
                self.controllers.substep(t_to, j / n, k - self.off, y, self.ridx, self.view, self.hold_k)
                values = {**values, **self.controllers.values()}
        return recovered

    def _safe_step(self, tw: _Twin, k: int, values: dict[str, float], t_from: float | None = None,
                   t_to: float | None = None, code: int | None = None) -> bool:
        """Step *tw* from row k to k+1 (or *t_from* to *t_to* within); recover from a solver failure.

        True if it had to recover. *code*: the step's ``tbn_advance`` already
        returned it (see :meth:`_Twin.step`).
        """
        grid = self.grid
        t_k = float(grid[k])
        t_from = t_k if t_from is None else t_from
        t_next = float(grid[k + 1]) if t_to is None else t_to
        try:
            tw.step(t_next, values, code)
            return False
        except SimulationError as exc:
            self.event(t_from, "solver-failure",
                       f"{tw.label} twin failed between {t_from:g} s and {t_next:g} s: {exc}")
        self.output.flush()
        try:
            if tw.me and tw.x is not None and math.isclose(tw.x_time, t_from, abs_tol=1e-9 * max(1.0, t_from)):
                tw.start(t_from, values, tw.x)
            else:
                tw.replay_csv(self.csv_path, k, grid)
                tw.stepper.set(tw.fmu_values(values))
                tw.applied.update(values)
                if t_from > t_k:
                    tw.step(t_from, values)
            tw.step(t_next, values)
            self.event(t_from, "recovered",
                       f"{tw.label} twin re-initialised from its state at {t_from:g} s and continued")
            return True
        except SimulationError as exc:
            self.event(t_from, "solver-failure", f"{tw.label} twin failed again after re-initialisation: {exc}")
        tw.start(t_from, values)  # cold start: fresh initialisation at t_from
        tw.step(t_next, values)  # a third failure propagates
        self.event(t_from, "cold-start", f"{tw.label} twin cold-started (fresh initialisation) at {t_from:g} s")
        return True

    def _row(self, k: int) -> tuple[dict[str, float], dict[str, float]]:
        """Read the twins, update the controllers and compensation, write row *k*.

        Returns the values to apply to the tracked twin (parameters and
        corrections) and to the untracked one (its corrections).
        """
        assert self.twin is not None
        view, plan, read, ridx = self.view, self.plan, self.read, self.ridx
        t = float(self.grid[k])
        y = self.twin.get(read)
        yu = self.plain.get(read) if self.plain is not None else (
            np.array([plan.untracked_table[n][k] for n in read]) if plan.untracked_table is not None
            else np.full(len(read), np.nan))
        i = k - self.off  # row k in the current window
        hold_all = t < self.hold_until - 1e-9 or bool(view.stopped[i]) or t < self.recovery_until - 1e-9
        if hold_all != self.hold_k:
            self.twin.force_restart = True  # entering or leaving a hold: the integrator restarts
        self.hold_k = hold_all
        modes = self.controllers.update(t, i, y, ridx, view, hold_all, self.event)
        for s in self.compensation.states:
            self.output.sstats[s.tag].add(float(y[ridx[s.variable]]))
        corr, corr_u = self.compensation.update(i, y, yu if self.plain is not None else None, ridx, view)
        params = self.controllers.values()
        row: list[Any] = [t]
        if self._columns[0] is not view:
            fits = self.output.fits
            self._columns = (view, [(ridx[plan.tag_var[tag]], view.samples[tag],
                                     view.scored[tag] if tag in fits else None, fits.get(tag))
                                    for tag in plan.out_tags])
        yl, yul = y.tolist(), yu.tolist()  # Python floats, as float() of the elements
        for j, samples, scored, fit in self._columns[1]:
            m = float(samples[i])
            a, b = yl[j], yul[j]
            row += (m, a, b)
            if scored is not None and scored[i]:
                fit.add(m, a, b)
        row += [params[n] for n in self.controllers.names]
        row += [corr[n] for n in self.compensation.names]
        row += [corr_u[n] for n in self.compensation.names]
        row += modes
        self.output.write(row)
        for n in self.controllers.names:
            self.output.pstats[n].add(params[n])
        for n in self.compensation.names:
            self.output.cstats[n].add(corr[n])
        return {**params, **corr}, corr_u

    def run(self, *, max_steps: int | None = None, progress: Callable[[int, int], None] | None = None) -> bool:
        """Step to the end (or *max_steps* rows); checkpoint on the way and at the end. True if complete."""
        assert self.twin is not None
        n_rows = self.n_rows
        rows_this_call = 0
        self.complete = True
        every = self.checkpoint_every
        while self.k < n_rows:
            k = self.k
            self._window_for(k)
            fast = self._native_rows() if k < n_rows - 1 else None
            if fast is not None:
                k_stop = min(n_rows - 1, (k // every + 1) * every)
                if max_steps is not None:
                    k_stop = min(k_stop, k + max_steps - rows_this_call)
                self._window_for(k, min(k_stop, k + fast.CAP))
                k_stop = min(k_stop, self._limit())
                written, pending, python = fast.run(self, k, k_stop)
                if progress is not None:
                    for j in range(written):
                        progress(k + j + 1, n_rows)
                rows_this_call += written
                self.native_rows += written
                if pending is not None:  # a twin's step inside the last row written needs Python
                    self._step_row(self.k, *pending)
                elif written and self.k % every == 0:
                    self._restart_point()
                if max_steps is not None and rows_this_call >= max_steps and self.k < n_rows:
                    self.complete = False
                    break
                if not python:
                    continue
                k = self.k  # the row that needs Python (a tag going missing or coming back, ...)
                self._window_for(k)
            values, corr_u = self._row(k)
            rows_this_call += 1
            if progress is not None:
                progress(k + 1, n_rows)
            if k == n_rows - 1:
                self.k += 1
                break
            self._step_row(k, values, corr_u)
            if max_steps is not None and rows_this_call >= max_steps and self.k < n_rows:
                self.complete = False
                break
        self.checkpoint()
        return self.complete

    def _step_row(self, k: int, values: dict[str, float], corr_u: dict[str, float],
                  resume: tuple[int, int, int] | None = None) -> None:
        """Step both twins from row k to k+1 (row k written) and move on to row k+1 (checkpoint on the way).

        *resume* ``(twin, j, code)``: a batch of rows stepped part of this row
        and the ``tbn_advance`` of the tracked (``twin`` 0, sub-step ``j``) or
        the untracked twin (1) returned *code*: go on from there.
        """
        which, j, code = resume if resume is not None else (-1, 1, None)
        recovered = False
        if which != 1:
            recovered = self._step_tracked(k, values, (j, code) if which == 0 else None)
        if self.plain is not None:
            try:
                self._safe_step(self.plain, k, dict(corr_u), code=code if which == 1 else None)
            except SimulationError as exc:
                # the comparison run is not worth stopping the tracking for
                self.event(float(self.grid[k]), "untracked-abandoned", f"untracked twin failed for good and "
                           f"is dropped (its columns are empty from here on): {exc}")
                self.plain.close()
                self.plain = None
        if recovered:
            self.recovery_until = float(self.grid[k + 1]) + self.recovery_hold
            self.event(float(self.grid[k]), "hold",
                       f"controllers on hold until t = {self.recovery_until:g} s after the recovery")
        self.k += 1
        if self.k % self.checkpoint_every == 0:
            self._restart_point()

    def _restart_point(self) -> None:
        """Checkpoint at row :attr:`k` and restart the twins there from their saved states."""
        self.checkpoint()
        # a checkpoint is a restart point: re-initialise from the saved states, exactly
        # as a resume would, so a resumed run is identical to an uninterrupted one
        for tw in (self.twin, self.plain):
            if tw is not None and tw.me and tw.x is not None:
                tw.start(float(self.grid[self.k]), dict(tw.applied), tw.x)

    def close(self) -> None:
        """Close the CSV and both twins."""
        self.output.close()
        for tw in (self.twin, self.plain):
            if tw is not None:
                tw.close()
        if self.stream is not None:
            self.stream.close()

    # ------------------------------------------------------------------ result

    def result(self) -> TrackingResult:
        """The run's :class:`TrackingResult` (also written to ``result.json``)."""
        grid, k, k0, ts = self.grid, self.k, self.k0, self.ts
        metric = self.view.window
        out = self.output
        restarts, carried = self.twin.counts() if self.twin is not None else (0, 0)
        result = TrackingResult(
            csv=self.csv_path,
            window=(max(metric[0], self.hold_until), min(metric[1], float(grid[-1]) + ts)),
            variables={t: f.result() for t, f in out.fits.items()},
            parameters={n: ParameterResult(s.final, s.min, s.max, p.bounds[0], p.bounds[1])
                        for (n, s), p in zip(out.pstats.items(), self.controllers.pairs)},
            corrections={n: ParameterResult(s.final, s.min, s.max, math.nan, math.nan)
                         for n, s in out.cstats.items()},
            states={n: ParameterResult(s.final, s.min, s.max, math.nan, math.nan) for n, s in out.sstats.items()},
            seconds=_time.perf_counter() - self.wall0,
            seconds_untracked=self.plain.step_seconds if self.plain is not None else math.nan,
            simulated_seconds=float(grid[min(k, self.n_rows - 1)] - grid[k0]) if k > k0 else 0.0,
            steps=k,
            complete=self.complete,
            events=tuple(self.events),
            restarts=restarts,
            carried=carried,
        )
        summary = {**result.to_json(), "complete": self.complete, "steps": k, "csv": str(self.csv_path),
                   "window": list(result.window),
                   "variables_detail": {t: {"samples": v.samples} for t, v in result.variables.items()},
                   "corrections": {n: {"final": _num(c.final), "min": _num(c.min), "max": _num(c.max)}
                                   for n, c in result.corrections.items()},
                   "states": {n: {"final": _num(c.final), "min": _num(c.min), "max": _num(c.max)}
                              for n, c in result.states.items()},
                   "events": [[e.time, e.kind, e.message] for e in self.events],
                   "integrator": {"restarts": restarts, "carried": carried},
                   **({"bands": out.bands.describe()} if out.bands is not None else {})}
        write_text_atomic(self.out_dir / RESULT_NAME, json.dumps(summary, indent=1))
        return result


def track(
    spec: Spec,
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
    view: MeasurementView | None = None,
    interpolation: Interpolation = "linear",
    substeps: int | Literal["auto"] = "auto",
    carry: float = CARRY_FRACTION,
    controllers: ControllerMode = "discrete",
    inputs_twin: Any = None,
    window_rows: int | None = None,
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
    view : trackingbox.data.MeasurementView, optional
        The measurements to track, when the caller has built them already
        (``MeasurementView.from_spec(spec, window, skip=spec.tracking.hold_until)``);
        default: built here from the spec.
    interpolation : {"linear", "zoh"}
        How the controllers see the error between samples (see
        :class:`~trackingbox.tracking.controllers.ScaledPI`). ``"linear"``
        (default): the error goes linearly from one sample to the next, as in
        the compiled box (interpolated measurement, continuous twin output);
        the parameter of row ``k`` is the controller's value at ``t_k``, held
        over ``[t_k, t_k+1]``. ``"zoh"``: the error held over the sample; the
        parameter of row ``k`` is the value at ``t_k+1``, applied from ``t_k``.
    substeps : int or "auto"
        ``"linear"`` only: integrate the PI controllers with the tracked twin
        over this many equal parts of each sample. After each part but the
        last the controllers read the twin, take the measurement interpolated
        between the two samples, advance and give the twin their new values,
        so a pair whose variable answers its parameter within a sample closes
        its loop within the sample, as in the compiled box (where the loop is
        continuous). Hold flags, state compensation, the CSV rows and the
        untracked twin stay per sample. ``"auto"`` (default): one part when
        every pair's within-sample loop gain (:func:`within_sample_gains`,
        measured on the twin before the run) is at most
        :data:`SUBSTEP_GAIN`, else ``ceil(sqrt(g / SUBSTEP_GAIN))`` for the
        largest, at most :data:`MAX_SUBSTEPS`. Needs a model-exchange twin
        (``"auto"`` chooses 1 for a co-simulation one). A checkpoint records
        the count; resuming with another is refused.
    carry : float
        Model exchange: the tracked twin's integrator (CVODE) is carried
        across a change of its parameters and correction flows instead of
        being re-initialised, when every change is at most this fraction of
        the parameter's bound range (a correction: of its compensator's gain
        times its level's measured range). CVODE then stops exactly at each
        sample and sub-step (its stop time), and the change becomes a jump of
        the derivatives that its error test absorbs. Larger changes, the
        start, entering or leaving a hold, a recovery and a checkpoint's
        restart point re-initialise it. ``0``: re-initialise at every change
        (the restart path). Default :data:`CARRY_FRACTION`.
    controllers : {"discrete", "continuous"}
        ``"discrete"`` (default): the controllers are the exact
        discretisations of the box's laws (:class:`ScaledPI`,
        :class:`StateCompensator`), updated at every sample (and sub-step);
        the twin's integrator stops at each. ``"continuous"``: the box's laws
        themselves, as continuous states integrated by CVODE together with
        the twin's states in the native right-hand side (``tbn_closed_rows``,
        see :class:`_ClosedRows`), the measurement interpolated linearly
        between samples as the compiled box sees it; CVODE returns at every
        sample (its stop time: the data's kinks) and is re-initialised only
        where a hold starts or ends or a tag goes missing or comes back, and
        at a checkpoint. It runs on the *inputs twin*
        (:func:`~trackingbox.generate.inputs_twin.inputs_twin`: the twin
        compiled with its tracked parameters switched to their conditional
        inputs), which it builds from the spec's ``[source]`` unless
        *inputs_twin* is given; it needs the native stepper, PI pairs and
        ``interpolation="linear"``; *substeps* and *carry* do not apply.
        Rows that need Python (a tag going missing or coming back, a solver
        failure) run on the discrete path.
    inputs_twin : trackingbox.generate.inputs_twin.InputsTwin, optional
        The compiled inputs twin for ``controllers="continuous"``.
    window_rows : int, optional
        Without *view*: the measurements are read once into a temporary file
        in *out_dir* and the run holds this many grid rows of them at a time
        (:class:`~trackingbox.stream.WindowedMeasurements`; default
        :data:`~trackingbox.stream.WINDOW_ROWS`), the twins' input tables
        too, so its memory does not grow with its length; the rows are the
        same as from the whole view. ``0``: the whole view. Data the windows
        cannot give exactly (a historian's long export, heartbeat tags, a tag
        bridging every gap) and a given *untracked* table take the whole view.

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
    loop = TrackingLoop(spec, out_dir=out_dir, window=window, untracked=untracked,
                        checkpoint_every=checkpoint_every, recovery_hold=recovery_hold, tolerance=tolerance,
                        view=view, interpolation=interpolation, substeps=substeps, carry=carry,
                        controllers=controllers, inputs_twin=inputs_twin, window_rows=window_rows)
    try:
        loop.begin(resume=resume)
        loop.run(max_steps=max_steps, progress=progress)
    finally:
        loop.close()
    return loop.result()
