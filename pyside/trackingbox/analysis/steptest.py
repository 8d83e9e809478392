"""Steady-state step tests on the twin FMU: the gain matrix ``G(0)`` for pairing.

Procedure (one run per parameter and direction, run in parallel):

1. Hold the FMU inputs at an operating point (from the measurements), start
   from the parameters' start values, controllers active, and run until the
   outputs settle.
2. Freeze the controllers (set the freeze inputs/parameters, e.g.
   ``holdControllers = 1``) and let the outputs settle again.
3. Step one parameter by ``+step`` (and, in a separate run, ``-step``) of its
   bound range and run until the outputs settle once more.

*Settled* means: over the last ``window`` seconds, every output moved by at
most ``tolerance`` times its range (its measured span, by default). A phase
that has not settled after ``max_time`` seconds is an :class:`AnalysisError`
naming the phase (and parameter) and the outputs still moving.

The first phases are computed once (the baseline run) and replayed
deterministically by each step run on the same communication grid.
"""
from __future__ import annotations

import logging
import math
import time as _time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..errors import AnalysisError, FMUError, TrackingError, unknown_name
from ..fmu import read_info
from ..simulation.models import cached_model

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class StepSettings:
    """How step tests run.

    Attributes
    ----------
    step : float
        Step size as a fraction of each parameter's bound range (``max - min``).
    two_sided : bool
        Also step by ``-step`` (linearity check); the gain is then the secant
        between the two.
    freeze : tuple of (str, float)
        FMU inputs or tunable parameters set after the first settle to freeze
        the twin's controllers (e.g. ``(("holdControllers", 1.0),)``); empty for
        models without controllers.
    interval : float
        Communication step (s): sampling of the responses.
    window : float
        Settle window (s).
    tolerance : float
        Allowed change of the (drift-corrected) step response over the
        window, as a fraction of each output's range.
    baseline_tolerance : float
        The same for the settle phases before the step (looser: what is left
        of their drift is removed by ``drift_correction``).
    max_time : float
        Longest time (s) any phase may take to settle.
    solver_tolerance : float
        FMU solver relative tolerance.
    warm_start : bool
        Start each step run from the baseline's continuous states at the step
        time (model-exchange FMUs) instead of replaying the settle phases.
    drift_correction : bool
        Run the baseline on without any step (a reference run) and measure each
        response against it, ``y_step(t) - y_ref(t)``, so a slow residual drift
        (a large tank still warming up) is not mistaken for a gain.
    reference_horizon : float, optional
        Length (s after the step time) of the first reference run. The reference
        run is on every step run's critical path (they are measured against it),
        so it first covers only this much of ``max_time``; a step run that needs
        more of it stops, and is run again against a reference four times as long
        (up to ``max_time``). A reference's values do not depend on how far it
        runs, so the results are those of a reference over the whole ``max_time``.
        Default (None): ``max(20 * window, max_time / 8)``, at most ``max_time``.
    """

    step: float = 0.05
    two_sided: bool = True
    freeze: tuple[tuple[str, float], ...] = ()
    interval: float = 10.0
    window: float = 600.0
    tolerance: float = 1e-4
    baseline_tolerance: float = 1e-3
    max_time: float = 86400.0
    solver_tolerance: float = 1e-8
    warm_start: bool = True
    drift_correction: bool = True
    reference_horizon: float | None = None

    def __post_init__(self) -> None:
        for name in ("step", "interval", "window", "tolerance", "baseline_tolerance", "max_time",
                     "solver_tolerance"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise AnalysisError(f"step-test setting {name} must be a positive number, got {value!r}")
        if self.window < self.interval:
            raise AnalysisError(f"step-test window ({self.window:g} s) is shorter than the interval "
                                f"({self.interval:g} s)")
        h = self.reference_horizon
        if h is not None and not (isinstance(h, (int, float)) and math.isfinite(h) and h > 0):
            raise AnalysisError(f"step-test setting reference_horizon must be a positive number, got {h!r}")

    def first_reference_horizon(self) -> float:
        """Seconds after the step time the first reference run covers (see ``reference_horizon``)."""
        h = self.reference_horizon if self.reference_horizon is not None else max(20.0 * self.window,
                                                                                   self.max_time / 8.0)
        return float(min(h, self.max_time))


@dataclass(frozen=True)
class StepTestResult:
    """Gain matrix and step-response figures.

    Rows are tracking variables (``variables``: measurement tags, simulated by
    ``outputs``), columns are parameters.

    Attributes
    ----------
    gains : ndarray, shape (m, n)
        Steady-state gains ``dy_i/dp_j`` (secant over the +/- steps when two-sided).
    gains_up, gains_down : ndarray, shape (m, n)
        One-sided gains (``gains_down`` is NaN when not two-sided).
    asymmetry : ndarray, shape (m, n)
        ``|g_up - g_down| / max(|g_up|, |g_down|)``; NaN where one-sided or where
        neither response exceeds the settle tolerance.
    time_constants : ndarray, shape (m, n)
        Time (s) to 63.2 % of the final change, mean of both directions; NaN
        where the response is below the settle tolerance.
    deltas : ndarray, shape (n,)
        Size of the +step of each parameter.
    baseline : ndarray, shape (m,)
        Outputs at the step time, controllers frozen.
    ranges : ndarray, shape (m,)
        Output ranges used by the settle rule.
    freeze_time, step_time : float
        When the controllers were frozen and when parameters were stepped (s).
    operating_point : dict
        Values set before initialisation besides the parameter starts: the
        held FMU inputs and the fixed parameters.
    runs : int
        Simulations made.
    seconds : float
        Wall-clock time.
    """

    variables: tuple[str, ...]
    outputs: tuple[str, ...]
    parameters: tuple[str, ...]
    gains: np.ndarray = field(repr=False, compare=False)
    gains_up: np.ndarray = field(repr=False, compare=False)
    gains_down: np.ndarray = field(repr=False, compare=False)
    asymmetry: np.ndarray = field(repr=False, compare=False)
    time_constants: np.ndarray = field(repr=False, compare=False)
    deltas: np.ndarray = field(repr=False, compare=False)
    baseline: np.ndarray = field(repr=False, compare=False)
    ranges: np.ndarray = field(repr=False, compare=False)
    freeze_time: float = math.nan
    step_time: float = math.nan
    operating_point: dict[str, float] = field(default_factory=dict)
    runs: int = 0
    seconds: float = 0.0

    def nonlinear(self, threshold: float = 0.2) -> list[tuple[str, str, float]]:
        """``(variable, parameter, asymmetry)`` where the +/- gains differ by more than *threshold*."""
        out = []
        for i, j in np.argwhere(np.nan_to_num(self.asymmetry, nan=0.0) > threshold):
            out.append((self.variables[i], self.parameters[j], float(self.asymmetry[i, j])))
        return out


# --------------------------------------------------------------------------- runs


@dataclass(frozen=True)
class RunPlan:
    """One simulation: baseline phases, then (optionally) a parameter change.

    Picklable, so it travels to worker processes. ``freeze_time`` and
    ``step_time`` are NaN in the baseline run (detected) and fixed in step runs.
    """

    fmu: str
    start_values: tuple[tuple[str, float], ...]
    outputs: tuple[str, ...]
    ranges: tuple[float, ...]
    settings: StepSettings
    freeze_time: float = math.nan
    step_time: float = math.nan
    change: tuple[tuple[str, float], ...] = ()
    label: str = "baseline"
    states: tuple[float, ...] | None = None
    compensation: tuple[tuple[str, str, float], ...] = ()
    levels_ref: tuple[float, ...] | None = None
    reference: np.ndarray | None = field(default=None, repr=False, compare=False)
    record: bool = False
    horizon: float | None = None  # reference run: seconds recorded after the step time (None: max_time)


@dataclass(frozen=True)
class RunResult:
    """What a :class:`RunPlan` produced."""

    label: str
    freeze_time: float
    step_time: float
    before: np.ndarray
    after: np.ndarray
    end_time: float
    times: np.ndarray
    trajectory: np.ndarray
    states: tuple[float, ...] | None = None
    levels_ref: tuple[float, ...] | None = None
    short: bool = False  # a step run that needed more of the reference than its plan carried


class _Settle:
    """Settle detector: span over a sliding window below tolerance x range."""

    def __init__(self, start: float, window: float, limits: np.ndarray) -> None:
        self.start = start
        self.window = window
        self.limits = limits
        self.buf: deque[tuple[float, np.ndarray]] = deque()

    def push(self, t: float, y: np.ndarray) -> bool:
        self.buf.append((t, y))
        while self.buf and self.buf[0][0] < t - self.window - 1e-9 * max(1.0, abs(t)):
            self.buf.popleft()
        if t - self.start < self.window - 1e-9 * max(1.0, abs(t)):
            return False
        return bool(np.all(self.spans() <= self.limits))

    def spans(self) -> np.ndarray:
        arr = np.array([y for _, y in self.buf])
        return arr.max(axis=0) - arr.min(axis=0)


def _still_moving(outputs: Sequence[str], spans: np.ndarray, limits: np.ndarray, window: float) -> str:
    parts = [f"{outputs[i]} moved {spans[i]:.3g} in the last {window:g} s (limit {limits[i]:.3g})"
             for i in np.flatnonzero(spans > limits)]
    return "; ".join(parts[:6]) + (" ..." if len(parts) > 6 else "")


def run_plan(plan: RunPlan) -> RunResult:
    """Execute one :class:`RunPlan` (in a worker; the FMU is opened once per process).

    Raises
    ------
    AnalysisError
        If a phase does not settle within ``max_time``.
    """
    s = plan.settings
    model = cached_model(plan.fmu, s.solver_tolerance)
    limits = np.asarray(plan.ranges, dtype=float) * s.tolerance
    base_limits = np.asarray(plan.ranges, dtype=float) * s.baseline_tolerance
    warm = plan.states is not None and not math.isnan(plan.step_time)
    t_start = plan.step_time if warm else 0.0
    start = dict(plan.start_values)
    if warm:
        start.update(dict(s.freeze))
    try:
        stepper = model.stepper(start_time=t_start, parameters=start, max_step=s.interval)
        if warm:
            stepper.set_continuous_states(np.asarray(plan.states, dtype=float))
    except TrackingError as exc:
        raise AnalysisError(f"step test {plan.label}: the twin could not be initialised: {exc}") from None
    outs = list(plan.outputs)
    k = int(round(t_start / s.interval))
    levels = [c[0] for c in plan.compensation]
    corrections = [c[1] for c in plan.compensation]
    comp_gain = np.array([c[2] for c in plan.compensation], dtype=float)
    ref: np.ndarray | None = None
    if warm and plan.compensation:
        ref = np.asarray(plan.levels_ref, dtype=float)

    def advance(kk: int) -> np.ndarray:
        try:
            if ref is not None:  # proportional state compensation holds the tank levels
                stepper.set(dict(zip(corrections, (comp_gain * (ref - stepper.get(levels))).tolist())))
            stepper.step(kk * s.interval)
        except TrackingError as exc:
            raise AnalysisError(f"step test {plan.label}: simulation failed at t = {kk * s.interval:g} s: "
                                f"{exc}") from None
        return stepper.get(outs)

    def settle(phase: str, k0: int) -> int:
        det = _Settle(k0 * s.interval, s.window, base_limits)
        det.push(k0 * s.interval, stepper.get(outs))
        kk = k0
        k_max = k0 + int(math.ceil(s.max_time / s.interval))
        while kk < k_max:
            kk += 1
            if det.push(kk * s.interval, advance(kk)):
                return kk
        raise AnalysisError(
            f"step test {plan.label}: {phase} did not settle within {s.max_time:g} s "
            f"(from t = {k0 * s.interval:g} s to {kk * s.interval:g} s): "
            f"{_still_moving(outs, det.spans(), base_limits, s.window)}; raise --max-time or check the "
            "twin is stable at this operating point")

    def run_to(k_target: int) -> None:
        nonlocal k
        while k < k_target:
            k += 1
            advance(k)

    # phase 1: controllers active
    if warm:
        pass
    elif math.isnan(plan.freeze_time):
        k = settle("the twin with its controllers active", 0)
    else:
        run_to(int(round(plan.freeze_time / s.interval)))
    freeze_time = plan.freeze_time if warm else k * s.interval
    if plan.compensation and ref is None:
        ref = (np.asarray(plan.levels_ref, dtype=float) if plan.levels_ref is not None
               else stepper.get(levels))
    # phase 2: controllers frozen
    if s.freeze and not warm:
        stepper.set(dict(s.freeze))
        if math.isnan(plan.step_time):
            k = settle("the twin after freezing its controllers (" +
                       ", ".join(f"{n} = {v:g}" for n, v in s.freeze) + ")", k)
        else:
            run_to(int(round(plan.step_time / s.interval)))
    step_time = k * s.interval
    before = stepper.get(outs)
    k_step = k
    n_max = int(math.ceil(s.max_time / s.interval))
    if plan.record:  # reference run: no change, the whole horizon
        n_rec = n_max if plan.horizon is None else min(n_max, int(math.ceil(plan.horizon / s.interval - 1e-9)))
        traj_ref = [before]
        for kk in range(k_step + 1, k_step + n_rec + 1):
            traj_ref.append(advance(kk))
        arr = np.array(traj_ref)
        return RunResult(plan.label, freeze_time, step_time, before, arr[-1], (k_step + n_rec) * s.interval,
                         s.interval * np.arange(k_step, k_step + n_rec + 1), arr)
    if not plan.change:
        states = None
        if s.warm_start:
            try:
                states = tuple(float(x) for x in stepper.get_continuous_states())
            except TrackingError:
                logger.info("no access to continuous states (co-simulation FMU): step runs replay the settle")
        return RunResult(plan.label, freeze_time, step_time, before, before, step_time,
                         np.array([step_time]), before[None, :], states,
                         None if ref is None else tuple(float(x) for x in ref))
    # phase 3: the step (measured against the reference run when there is one)
    ref_traj = plan.reference
    stepper.set(dict(plan.change))
    det = _Settle(step_time, s.window, limits)
    det.push(step_time, before)
    times = [step_time]
    traj = [before]
    k_max = k + n_max
    while True:
        if k >= k_max:
            raise AnalysisError(
                f"step test {plan.label}: the response did not settle within {s.max_time:g} s of the step "
                f"at t = {step_time:g} s: {_still_moving(outs, det.spans(), limits, s.window)}")
        k += 1
        if ref_traj is not None and k - k_step >= len(ref_traj):  # past a shortened reference: run again
            return RunResult(plan.label, freeze_time, step_time, before, traj[-1], (k - 1) * s.interval,
                             np.array(times), np.array(traj), short=True)
        y = advance(k)
        if ref_traj is not None:
            y = before + (y - ref_traj[k - k_step])
        times.append(k * s.interval)
        traj.append(y)
        if det.push(k * s.interval, y):
            break
    return RunResult(plan.label, freeze_time, step_time, before, traj[-1], k * s.interval,
                     np.array(times), np.array(traj))


#: ``progress(done, total)``, called after each finished run.
Progress = Callable[[int, int], None]


def run_all(plans: Sequence[RunPlan], executor: Executor | None = None,
            progress: Progress | None = None) -> list[RunResult]:
    """Run *plans* (in parallel on *executor*), results in plan order.

    The first failure cancels the runs not yet started and is raised.
    """
    total = len(plans)
    if executor is None:
        out = []
        for k, p in enumerate(plans):
            out.append(run_plan(p))
            if progress:
                progress(k + 1, total)
        return out
    futures = {executor.submit(run_plan, p): k for k, p in enumerate(plans)}
    results: list[RunResult | None] = [None] * total
    try:
        for done, f in enumerate(as_completed(futures), start=1):
            results[futures[f]] = f.result()
            logger.debug("done: %s", plans[futures[f]].label)
            if progress:
                progress(done, total)
    except BaseException:
        for f in futures:
            f.cancel()
        raise
    return [r for r in results if r is not None]


def time_to_63(times: npt.ArrayLike, y: npt.ArrayLike, y0: float, y_end: float) -> float:
    """Time from ``times[0]`` until ``y`` first covers 63.2 % of ``y_end - y0`` (linear interpolation).

    Examples
    --------
    >>> t = np.arange(0.0, 60.0, 1.0)
    >>> round(time_to_63(t, 1 - np.exp(-t / 10.0), 0.0, 1.0), 1)
    10.0
    """
    t = np.asarray(times, dtype=float)
    frac = (np.asarray(y, dtype=float) - y0) / (y_end - y0)
    target = 1.0 - math.exp(-1.0)
    hit = np.flatnonzero(frac >= target)
    if hit.size == 0:
        return math.nan
    i = int(hit[0])
    if i == 0:
        return 0.0
    f0, f1 = frac[i - 1], frac[i]
    return float(t[i - 1] + (target - f0) / (f1 - f0) * (t[i] - t[i - 1]) - t[0])


# ------------------------------------------------------------------ operating point


def operating_point(measurements: pd.DataFrame, inputs: Mapping[str, str], *, start: float = 0.0,
                    duration: float = 3600.0, at: float | None = None) -> dict[str, float]:
    """FMU input values for the step tests, from measurements.

    Parameters
    ----------
    measurements : DataFrame
        ``time`` (s) and one column per tag.
    inputs : mapping
        Tag -> FMU input (the spec's ``[inputs]``).
    start, duration : float
        Mean over ``[start, start + duration)`` (the first hour of the training
        window by default).
    at : float, optional
        Instead, the values interpolated at this time.

    Returns
    -------
    dict
        FMU input name -> value.

    Raises
    ------
    AnalysisError
        If a tag is missing or has no valid sample in the window.
    """
    if "time" not in measurements.columns:
        raise AnalysisError("measurements have no 'time' column")
    t = measurements["time"].to_numpy(dtype=float)
    out: dict[str, float] = {}
    problems = []
    for tag, name in inputs.items():
        if tag not in measurements.columns:
            problems.append(unknown_name("tag", tag, [c for c in measurements.columns if c != "time"],
                                         "the measurements"))
            continue
        col = measurements[tag].to_numpy(dtype=float)
        ok = np.isfinite(col)
        if at is not None:
            if not ok.any():
                problems.append(f"tag {tag!r} has no valid samples")
                continue
            value = float(np.interp(at, t[ok], col[ok]))
        else:
            sel = ok & (t >= start) & (t < start + duration)
            if not sel.any():
                problems.append(f"tag {tag!r} has no valid samples between {start:g} s and {start + duration:g} s")
                continue
            value = float(col[sel].mean())
        out[name] = value
    if problems:
        raise AnalysisError("cannot take the operating point: " + "; ".join(problems))
    return out


# ------------------------------------------------------------------ the step tests


@dataclass(frozen=True)
class StepProblem:
    """What to step and what to watch: the picklable core shared with Sobol.

    Attributes
    ----------
    fmu : str
        Twin FMU path.
    variables : tuple of str
        Tracking-variable names (tags).
    outputs : tuple of str
        FMU outputs simulating them (same order).
    parameters : tuple of str
        Candidate parameters.
    starts, lower, upper : tuple of float
        Start value and bounds of each parameter.
    fixed : tuple of (str, float)
        Other values set before initialisation (known parameters, operating point).
    ranges : tuple of float
        Output ranges for the settle rule and the scaling.
    compensation : tuple of (level variable, correction input, gain)
        Tank levels held by proportional state compensation from the freeze
        on (``correction = gain * (level at freeze - level)``), so that
        integrating levels neither drift nor run dry while the controllers
        are frozen (the spec's ``[[states]]``).
    """

    fmu: str
    variables: tuple[str, ...]
    outputs: tuple[str, ...]
    parameters: tuple[str, ...]
    starts: tuple[float, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    fixed: tuple[tuple[str, float], ...] = ()
    ranges: tuple[float, ...] = ()
    compensation: tuple[tuple[str, str, float], ...] = ()

    def start_values(self) -> tuple[tuple[str, float], ...]:
        """Values set before initialisation: fixed values, then parameter starts."""
        return tuple(self.fixed) + tuple(zip(self.parameters, self.starts))


def make_problem(fmu: str | Path, *, outputs: Mapping[str, str], parameters: Sequence[tuple[str, float, float, float]],
                 fixed: Mapping[str, float] | None = None, operating: Mapping[str, float] | None = None,
                 ranges: Mapping[str, float] | None = None, freeze: Mapping[str, float] | None = None,
                 compensation: Sequence[tuple[str, str, float]] = ()) -> StepProblem:
    """Check names against the FMU and build a :class:`StepProblem`.

    Parameters
    ----------
    fmu : path
        Twin FMU.
    outputs : mapping
        Tag -> FMU output (the spec's ``[outputs]``).
    parameters : sequence of (name, start, min, max)
        Candidate parameters.
    fixed : mapping, optional
        Known parameter values.
    operating : mapping, optional
        FMU input values to hold.
    ranges : mapping, optional
        Tag -> range (measured span) for the settle rule and scaling; missing
        tags are filled by :func:`default_ranges`.
    freeze : mapping, optional
        Freeze names, checked to exist as inputs or tunable parameters.
    compensation : sequence of (level variable, correction input, gain), optional
        State compensation during the frozen phases (see :class:`StepProblem`).

    Raises
    ------
    AnalysisError
        Naming every unknown name, with "did you mean".
    """
    try:
        info = read_info(fmu)
    except FMUError as exc:
        raise AnalysisError(str(exc)) from None
    names = {v.name: v for v in info.variables}
    tunable = set(info.tunable_parameters)
    settable = tunable | set(info.inputs)
    problems: list[str] = []
    where = f"FMU {Path(fmu).name}"
    for tag, out in outputs.items():
        if out not in names:
            problems.append(unknown_name("output", out, info.outputs or list(names), where) + f" (for tag {tag!r})")
    for name, start, lo, hi in parameters:
        if name not in tunable:
            if name in names:
                problems.append(f"parameter {name!r} of {where} is not a tunable parameter "
                                f"(causality {names[name].causality}, variability {names[name].variability})")
            else:
                problems.append(unknown_name("parameter", name, sorted(tunable), where))
        if not (lo < hi):
            problems.append(f"parameter {name!r} has bounds [{lo:g}, {hi:g}]: min must be below max")
    for name in (freeze or {}):
        if name not in settable:
            problems.append(unknown_name("freeze input/parameter", name, sorted(settable), where))
    for name in (operating or {}):
        if name not in names:
            problems.append(unknown_name("input", name, info.inputs, where))
    for level, corr, gain in compensation:
        if level not in names:
            problems.append(unknown_name("level variable", level, list(names), where))
        if corr not in settable:
            problems.append(unknown_name("correction input", corr, sorted(settable), where))
        if not gain > 0:
            problems.append(f"state-compensation gain for {level!r} must be positive, got {gain}")
    if not outputs:
        problems.append("no tracking variables: the spec's [outputs] table is empty")
    if not parameters:
        problems.append("no candidate parameters: the spec has no [[parameters]]")
    if problems:
        raise AnalysisError("; ".join(problems))
    tags = tuple(outputs)
    fixed_items = tuple((k, float(v)) for k, v in (fixed or {}).items())
    fixed_items += tuple((k, float(v)) for k, v in (operating or {}).items())
    rng = tuple(float((ranges or {}).get(tag, math.nan)) for tag in tags)
    return StepProblem(
        fmu=str(Path(fmu).resolve()), variables=tags, outputs=tuple(outputs[t] for t in tags),
        parameters=tuple(p[0] for p in parameters), starts=tuple(float(p[1]) for p in parameters),
        lower=tuple(float(p[2]) for p in parameters), upper=tuple(float(p[3]) for p in parameters),
        fixed=fixed_items, ranges=rng,
        compensation=tuple((str(a), str(b), float(c)) for a, b, c in compensation))


def default_ranges(problem: StepProblem, settings: StepSettings) -> tuple[float, ...]:
    """Fill missing/non-positive ranges with ``max(|y(0)|, 1e-3)`` from the initialised twin."""
    rng = np.asarray(problem.ranges if problem.ranges else [math.nan] * len(problem.outputs), dtype=float)
    missing = ~(np.isfinite(rng) & (rng > 0))
    if not missing.any():
        return tuple(float(x) for x in rng)
    model = cached_model(problem.fmu, settings.solver_tolerance)
    st = model.stepper(start_time=0.0, parameters=dict(problem.start_values()), max_step=settings.interval)
    y0 = st.get(list(problem.outputs))
    rng[missing] = np.maximum(np.abs(y0[missing]), 1e-3)
    for i in np.flatnonzero(missing):
        logger.info("no range for %s: settle rule uses |y(0)| = %.4g", problem.variables[i], rng[i])
    return tuple(float(x) for x in rng)


def baseline(problem: StepProblem, settings: StepSettings, executor: Executor | None = None) -> RunResult:
    """Run phases 1-2 once (controllers active, then frozen) and return when they settled."""
    plan = RunPlan(problem.fmu, problem.start_values(), problem.outputs, problem.ranges, settings,
                   compensation=problem.compensation)
    if executor is None:
        return run_plan(plan)
    return executor.submit(run_plan, plan).result()


def reference_run(problem: StepProblem, settings: StepSettings, base: RunResult,
                  executor: Executor | None = None, horizon: float | None = None) -> np.ndarray | None:
    """Outputs of the unstepped twin from the step time over *horizon* s (default ``max_time``; None without
    drift correction)."""
    if not settings.drift_correction:
        return None
    plan = RunPlan(problem.fmu, problem.start_values(), problem.outputs, problem.ranges, settings,
                   base.freeze_time, base.step_time, (), label="reference run", states=base.states,
                   compensation=problem.compensation, levels_ref=base.levels_ref, record=True, horizon=horizon)
    res = run_plan(plan) if executor is None else executor.submit(run_plan, plan).result()
    drift = np.abs(res.trajectory - res.trajectory[0]).max(axis=0)
    for i in np.flatnonzero(drift > np.asarray(problem.ranges) * settings.tolerance):
        logger.info("%s drifts by %.3g over %g s without a step: responses are measured against that drift",
                    problem.outputs[i], drift[i], res.end_time - res.step_time)
    return res.trajectory


def run_against_reference(problem: StepProblem, settings: StepSettings, base: RunResult,
                          plans: Sequence[RunPlan], executor: Executor | None = None,
                          progress: Progress | None = None) -> tuple[np.ndarray | None, list[RunResult], int]:
    """The reference run and *plans* measured against it: ``(reference, results, runs)``.

    The reference is on every plan's critical path, so it first covers
    :meth:`StepSettings.first_reference_horizon`; the plans that run past it
    (:attr:`RunResult.short`) are run again against one four times as long, up
    to ``max_time``. The results are those against a reference over the whole
    ``max_time`` (a reference's values do not depend on how far it runs);
    *runs* counts every run made, re-runs included.
    """
    if not settings.drift_correction:
        return None, run_all(plans, executor, progress), len(plans)
    total = len(plans)
    results: list[RunResult | None] = [None] * total
    todo = list(range(total))
    horizon = settings.first_reference_horizon()
    finished = runs = 0
    while True:
        reference = reference_run(problem, settings, base, executor, horizon=horizon)
        counted = None if progress is None else (lambda done, _n, f=finished: progress(min(f + done, total), total))
        batch = run_all([replace(plans[i], reference=reference) for i in todo], executor, counted)
        runs += 1 + len(todo)
        short = [i for i, r in zip(todo, batch) if r.short]
        for i, r in zip(todo, batch):
            if not r.short:
                results[i] = r
        finished = total - len(short)
        if not short:
            return reference, [r for r in results if r is not None], runs
        if horizon >= settings.max_time:  # cannot happen: a full reference covers every step's run
            raise AnalysisError(f"step test {plans[short[0]].label}: ran past a reference run over max_time")
        logger.info("%d of %d runs need more than %g s of the reference run: extending it", len(short), total,
                    horizon)
        horizon = min(settings.max_time, 4.0 * horizon)
        todo = short


def step_tests(problem: StepProblem, settings: StepSettings = StepSettings(),
               executor: Executor | None = None, progress: Progress | None = None) -> StepTestResult:
    """Steady-state gain matrix of the twin by parameter step tests.

    Parameters
    ----------
    problem : StepProblem
        From :func:`make_problem`.
    settings : StepSettings
    executor : concurrent.futures.Executor, optional
        Runs the step tests in parallel (see :func:`~trackingbox.analysis.executor.make_executor`);
        serial in this process when omitted.
    progress : callable, optional
        ``progress(done, total)`` after each step run.

    Returns
    -------
    StepTestResult

    Raises
    ------
    AnalysisError
        A phase or a step that does not settle, a simulation failure.
    """
    t_wall = _time.perf_counter()
    if not all(math.isfinite(r) and r > 0 for r in problem.ranges) or len(problem.ranges) != len(problem.outputs):
        problem = replace(problem, ranges=default_ranges(problem, settings))
    base = baseline(problem, settings, executor)
    logger.info("baseline settled: controllers frozen at t = %g s, steady at t = %g s",
                base.freeze_time, base.step_time)
    plans: list[tuple[int, int, RunPlan]] = []
    n = len(problem.parameters)
    deltas = np.zeros(n)
    for j, (name, p0, lo, hi) in enumerate(zip(problem.parameters, problem.starts, problem.lower, problem.upper)):
        d = settings.step * (hi - lo)
        deltas[j] = d
        signs = (1, -1) if settings.two_sided else (1,)
        for sgn in signs:
            value = p0 + sgn * d
            if value > hi or value < lo:
                logger.warning("step of %s to %g leaves its bounds [%g, %g]", name, value, lo, hi)
            plans.append((j, sgn, RunPlan(problem.fmu, problem.start_values(), problem.outputs, problem.ranges,
                                          settings, base.freeze_time, base.step_time, ((name, value),),
                                          label=f"{'+' if sgn > 0 else '-'}{settings.step:g} step of {name}",
                                          states=base.states, compensation=problem.compensation,
                                          levels_ref=base.levels_ref)))
    reference, results, runs = run_against_reference(problem, settings, base, [p for _, _, p in plans], executor,
                                                     progress)
    m = len(problem.outputs)
    g_up = np.full((m, n), math.nan)
    g_dn = np.full((m, n), math.nan)
    tau_up = np.full((m, n), math.nan)
    tau_dn = np.full((m, n), math.nan)
    dy_up = np.full((m, n), math.nan)
    dy_dn = np.full((m, n), math.nan)
    limits = np.asarray(problem.ranges) * settings.tolerance
    for (j, sgn, _), r in zip(plans, results):
        dy = r.after - r.before
        g = dy / (sgn * deltas[j])
        taus = np.array([time_to_63(r.times, r.trajectory[:, i], r.before[i], r.after[i])
                         if abs(dy[i]) > limits[i] else math.nan for i in range(m)])
        if sgn > 0:
            g_up[:, j], tau_up[:, j], dy_up[:, j] = g, taus, dy
        else:
            g_dn[:, j], tau_dn[:, j], dy_dn[:, j] = g, taus, dy
    if settings.two_sided:
        gains = (dy_up - dy_dn) / (2.0 * deltas[None, :])
        with np.errstate(all="ignore"):
            asym = np.abs(g_up - g_dn) / np.maximum(np.abs(g_up), np.abs(g_dn))
        small = (np.abs(dy_up) <= limits[:, None]) & (np.abs(dy_dn) <= limits[:, None])
        asym[small] = math.nan
        tau = _nanmean2(tau_up, tau_dn)
    else:
        gains = g_up.copy()
        asym = np.full((m, n), math.nan)
        tau = tau_up
    result = StepTestResult(
        variables=problem.variables, outputs=problem.outputs, parameters=problem.parameters,
        gains=gains, gains_up=g_up, gains_down=g_dn, asymmetry=asym, time_constants=tau, deltas=deltas,
        baseline=base.before, ranges=np.asarray(problem.ranges, dtype=float), freeze_time=base.freeze_time,
        step_time=base.step_time, operating_point=dict(problem.fixed),
        runs=1 + runs, seconds=_time.perf_counter() - t_wall)
    for v, p, a in result.nonlinear():
        logger.warning("response of %s to %s is asymmetric (+/- step gains differ by %.0f %%)", v, p, 100 * a)
    return result


def _nanmean2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Element-wise mean of two arrays ignoring NaN (NaN where both are NaN)."""
    both = np.isfinite(a) & np.isfinite(b)
    return np.where(both, (a + b) / 2.0, np.where(np.isfinite(a), a, b))


def farthest_operating_point(measurements: pd.DataFrame, inputs: Mapping[str, str], reference: Mapping[str, float],
                             *, start: float, stop: float, duration: float = 3600.0,
                             min_distance: float = 0.05) -> tuple[float, dict[str, float]] | None:
    """The operating point of the window that differs most from *reference*: a second point for step tests.

    The window ``[start, stop)`` is cut into whole spans of *duration*; each
    span's mean inputs are compared with *reference* by relative differences,
    ``sqrt(sum(((u - u_ref) / max(|u|, |u_ref|))^2))`` (so a load that varies by
    half counts far more than a temperature that varies by a few kelvin out
    of 300).

    Parameters
    ----------
    measurements : DataFrame
        ``time`` (s from the first sample) and one column per tag.
    inputs : mapping
        Tag -> FMU input.
    reference : mapping
        FMU input -> value at the first operating point.
    start, stop, duration : float
        Window and span length (s).
    min_distance : float
        Below this relative distance the window has no second operating point.

    Returns
    -------
    (float, dict) or None
        Start time of the span and its FMU input values; None when no span
        differs by at least *min_distance*.

    Examples
    --------
    >>> t = np.arange(0.0, 4 * 3600.0, 60.0)
    >>> df = pd.DataFrame({"time": t, "F": np.where(t < 7200, 1.0, 2.0), "T": 300.0 + 0 * t})
    >>> farthest_operating_point(df, {"F": "f", "T": "temp"}, {"f": 1.0, "temp": 300.0}, start=0, stop=t[-1] + 60)
    (7200.0, {'f': 2.0, 'temp': 300.0})
    """
    t = measurements["time"].to_numpy(dtype=float)
    best: tuple[float, float, dict[str, float]] | None = None
    k = 0
    while start + (k + 1) * duration <= stop + 1e-9:
        a = start + k * duration
        sel = (t >= a) & (t < a + duration)
        k += 1
        values: dict[str, float] = {}
        for tag, name in inputs.items():
            col = measurements.loc[sel, tag].to_numpy(dtype=float) if tag in measurements.columns else np.array([])
            col = col[np.isfinite(col)]
            if not col.size:
                break
            values[name] = float(col.mean())
        else:
            d2 = 0.0
            for name, u in values.items():
                ref = float(reference.get(name, u))
                scale = max(abs(u), abs(ref))
                if scale > 0:
                    d2 += ((u - ref) / scale) ** 2
            dist = math.sqrt(d2)
            if best is None or dist > best[0]:
                best = (dist, a, values)
    if best is None or best[0] < min_distance:
        return None
    return float(best[1]), best[2]
