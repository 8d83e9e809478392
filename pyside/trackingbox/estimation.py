"""Bounded gray-box estimation of a twin's parameters from measurements.

The spec's ``[[parameters]]`` (start, min, max) are estimated on the training
window and judged on the validation window. Two stages:

1. **Global search**: :func:`scipy.optimize.differential_evolution`, seeded,
   bounded, Latin-hypercube first population with the start values in it; the
   population can be evaluated in parallel over ``workers`` processes (each
   worker process opens the FMU once and keeps it for every later evaluation).
   Its cost is simulated on a coarser grid (:data:`DEFAULT_GLOBAL_GRID`, inputs
   averaged over it, :func:`coarsen`), which is several times cheaper; the best
   point of each generation is scored on the full grid, and that is what is kept.
   The default number of generations is capped by a simulation budget
   (:func:`default_maxiter`), so many-parameter twins stay affordable.
2. **Local refinement**: :func:`scipy.optimize.least_squares` (trust-region
   reflective, bounded, ``x_scale`` = the bound ranges) on the residual vector,
   started from the best point so far. Its Jacobian is either *exact*: the
   forward sensitivity equations integrated with the twin in the same run that
   gives the residuals, from the FMU's directional derivatives
   (:mod:`trackingbox.sensitivity`; ``jacobian="exact"``, or ``"auto"`` where the
   twin provides them), or a forward difference on all parameters with a step of
   :data:`DIFF_STEP` times each bound range (:func:`jacobian_points`), the ``n``
   simulations spread over the workers (``"fd"``, and ``"auto"``'s fallback). With
   several output tags a second pass reweights each tag by ``1 / NRMSE_tag`` at
   the first pass's point (iteratively reweighted least squares), so that its
   steps follow the mean NRMSE itself. A refined point is kept only if it does
   not raise the cost.

Cost
----
For each output tag of the spec's ``[outputs]`` the normalised root-mean-square
error over the window,

``NRMSE_tag = sqrt(mean((y_sim - y_meas)**2)) / (max(y_meas) - min(y_meas))``,

where the mean, max and min are taken over the tag's *valid* samples in the
window only (not NaN, not in a gap longer than ``data.max_gap``, not in a
stoppage period nor its settle time). The global stage minimises the mean of
``NRMSE_tag`` over the tags. The refinement minimises the sum of squares of the
residual vector ``(y_sim - y_meas) / (range_tag * sqrt(n_tag * n_tags))``, i.e.
the mean of ``NRMSE_tag**2`` -- the smooth form of the same cost; both have the
same minimiser for a single tag.

Initial states
--------------
The twin FMU starts from its own start values, not from the plant's state. Each
simulation therefore begins ``warmup`` seconds (default :data:`DEFAULT_WARMUP`)
before its window, with the candidate parameters applied, and that warm-up is
never scored:

* where measurements precede the window (the validation window), the twin runs
  through them (*lead-in*, measured inputs), so slow states follow the history;
* the rest (all of it for a window at the first sample) is a *steady-state
  pre-run*: the inputs held at their first values, rounded up to whole sample
  times.

States that integrate (tank levels whose in- and outflows do not balance at the
first input values) drift during a held pre-run; give such twins a short
``warmup`` or a level controller.

Grid
----
Every window is taken from the spec's measurement view
(:class:`trackingbox.data.MeasurementView`), the one tracking and validation
use: grid points ``k * sample_time`` from the first sample, each tag
resampled onto them separately (linear interpolation between that tag's valid
samples, never across a gap longer than ``data.max_gap``, or, without it,
:func:`trackingbox.data.default_max_gap`: 2.5 times the tag's median sampling
interval). Output samples that are NaN, in a long gap, or in a stoppage
(``data.stoppage``: the tag below the threshold, plus ``settle`` seconds
after) are left out of the cost (the view's ``scored`` samples). Inputs must
be valid over the whole window, otherwise the twin cannot be simulated
(:class:`~trackingbox.errors.DataError` naming the tag and the span).
"""
from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from .checkpoint import Journal
from .errors import DataError, EstimationError, SimulationError, SpecError, TrackingError, unknown_name
from .io import write_text_atomic

if TYPE_CHECKING:
    from .spec import Spec

log = logging.getLogger(__name__)

#: Default warm-up before each window (s): lead-in through the measured history where there is
#: some, else a held-input pre-run. Long enough for tank temperatures (time constants of hours)
#: to settle; the held part costs little because the solver takes long steps there.
DEFAULT_WARMUP = 4 * 3600.0
#: Default number of differential-evolution generations for a small problem; see
#: :func:`default_maxiter` for the budget that applies to many parameters.
DEFAULT_MAXITER = 30
#: Default budget of the global search in simulations (coarse grid): the default number of
#: generations is the most that keeps ``population * (generations + 1)`` within it.
DEFAULT_GLOBAL_EVALUATIONS = 480
#: Default population of differential evolution, in all (not per parameter): scipy's usual
#: 15 per parameter is unaffordable when one simulation takes seconds and there are a dozen
#: parameters; the refinement does the fine work. The population is ``max(2, ceil(15 / n))``
#: per parameter: 15 for one parameter, 28 for fourteen.
DEFAULT_POPULATION = 15
#: Grid step of the global search's cost (s): the training window is simulated and scored on
#: the largest multiple of ``sample_time`` not above this (inputs averaged over it), which makes
#: each of its many simulations several times cheaper. The refinement and the reported NRMSE
#: always use the full ``sample_time`` grid.
DEFAULT_GLOBAL_GRID = 60.0
#: The global search stops once the better half of its population (by coarse cost) lies within
#: this fraction of every parameter's bound range: the population agrees on one basin, and the
#: refinement (Gauss-Newton steps on the exact Jacobian) walks the rest of the way in a few runs,
#: where differential evolution would spend a population's worth of runs per generation
#: contracting onto the same point. Not the best point's movement: a best point that no trial
#: beat for a few generations may still be far from the minimum. 0 (``settle=0``): run every
#: generation.
GLOBAL_SETTLE = 0.1
#: Each output tag needs at least this many valid samples in each window.
MIN_VALID_SAMPLES = 20
#: Cost returned for a parameter set whose simulation fails (NRMSE units; a fit is << 1).
FAILED_COST = 1.0e3
#: Finite-difference step of the refinement's Jacobian, as a fraction of each parameter's
#: bound range (not of its value: a pipe coefficient near its lower bound would otherwise get
#: a step lost in solver noise). Forward differences, taken backwards at the upper bound.
DIFF_STEP = 1.0e-3

#: How the refinement's Jacobian is computed: ``"exact"`` (sensitivity equations from the FMU's
#: directional derivatives, one run for residuals and Jacobian), ``"fd"`` (forward differences,
#: ``1 + n`` runs), ``"auto"`` (the default: fd where the twin's runs are native, see
#: :func:`jacobian_support`; else exact where the twin supports it, else fd),
#: ``"prefer-exact"`` (exact where the twin supports it, else fd: for a caller that wants the
#: more accurate refinement whatever it costs, such as diagnosis's null model).
JACOBIAN_METHODS = ("auto", "exact", "fd", "prefer-exact")

#: The refinement stops when the next Gauss-Newton step (from the Jacobian at the accepted point,
#: projected on the bounds) moves no parameter by more than this fraction of its bound range. The
#: twin's cost carries the integrator's noise (about 1e-4 of its value at rtol 1e-6 near the
#: optimum), so least squares' own ``ftol`` of 1e-6 is met only by chance there, and the steps it
#: keeps taking (measured on the heat-exchanger bench: 2e-6 to 1.5e-5 of the range) move nothing
#: that matters: the statistical uncertainty of an estimate is orders of magnitude above.
REFINE_STEP_TOLERANCE = 1.0e-5

#: Refinement budget per pass: least-squares iterations (each costs 1 + n_parameters simulations,
#: the n of the Jacobian in parallel over the workers).
MAX_REFINE_ITERATIONS = 20

#: ``progress(stage, iteration, total, cost)``: stage ``"global"`` after each generation (best mean NRMSE),
#: ``"refine"`` after each refinement simulation (root mean square of the tags' NRMSE at that point, the
#: budget as total), ``"local"`` once when the refinement is done (best mean NRMSE).
ProgressCallback = Callable[[str, int, int, float], None]


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class EstimationResult:
    """What :func:`estimate` found.

    Attributes
    ----------
    parameters
        Estimated value of each estimated parameter (spec order).
    training_nrmse, validation_nrmse
        NRMSE per output tag at the estimate on the training / validation window.
    validation_nrmse_initial
        NRMSE per output tag on the validation window at the spec's start values.
    evaluations
        Number of twin simulations run on the training window (both stages,
        including the refinement's finite differences).
    seconds
        Wall time of the whole estimation.
    history
        Training cost (mean NRMSE) at the start values, then the best cost after
        each generation of the global search, then after the refinement.
    initial
        The start values the estimation began from.
    bounds
        ``(min, max)`` of each parameter.
    warmup
        Length of the steady-state pre-run used before each window (s).
    refinement
        How the local refinement ran: ``jacobian`` (``"exact"`` or ``"fd"``, what
        was used), ``requested`` (the ``jacobian`` setting), ``reason`` (why not
        exact, when it is not), ``runs`` (twin runs of the refinement; an exact
        run gives residuals and Jacobian together), ``seconds`` and ``cpu_seconds``
        (wall and process CPU time of the refinement; not in :meth:`to_json`, whose
        document a resumed run reproduces exactly). Empty without refinement.
    identifiability
        What the data could determine at the start values, checked before the search
        (:func:`trackingbox.identify.analysis.identify`, its ``to_json``); empty if not run.
    uncertainty
        Confidence intervals at the estimate (:class:`trackingbox.identify.intervals.Uncertainty`),
        or None.
    """

    parameters: dict[str, float]
    training_nrmse: dict[str, float]
    validation_nrmse: dict[str, float]
    validation_nrmse_initial: dict[str, float]
    evaluations: int
    seconds: float
    history: tuple[float, ...]
    initial: dict[str, float] = field(default_factory=dict)
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    warmup: float = DEFAULT_WARMUP
    refinement: dict[str, Any] = field(default_factory=dict)
    identifiability: dict[str, Any] = field(default_factory=dict)
    uncertainty: Any = None

    def to_json(self) -> dict[str, Any]:
        """The ``trackingbox estimate --json`` document."""
        out = {
            "parameters": dict(self.parameters),
            "training": {"nrmse": dict(self.training_nrmse)},
            "validation": {
                "nrmse": dict(self.validation_nrmse),
                "nrmse_initial": dict(self.validation_nrmse_initial),
            },
            "evaluations": int(self.evaluations),
            "seconds": float(self.seconds),
        }
        if self.refinement:  # its timings stay out: a resumed run's document equals an uninterrupted one's
            out["refinement"] = {k: v for k, v in self.refinement.items() if k not in ("seconds", "cpu_seconds")}
        if self.identifiability:  # trackingbox.identify: the check before, the intervals after
            out["identifiability"] = self.identifiability
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty.to_json()
        return out


def nrmse(simulated: npt.ArrayLike, measured: npt.ArrayLike) -> float:
    """Root-mean-square error divided by the measured range, over valid samples.

    Samples where *measured* is NaN are ignored. A constant measurement (zero
    range) is normalised by ``max(|mean|, 1)`` instead.

    >>> round(nrmse([1.0, 2.0, 4.0], [1.0, 3.0, 5.0]), 4)
    0.2041
    """
    sim = np.asarray(simulated, dtype=float)
    meas = np.asarray(measured, dtype=float)
    ok = np.isfinite(meas)
    if not ok.any():
        return math.nan
    err = sim[ok] - meas[ok]
    return float(np.sqrt(np.mean(err * err)) / _scale(meas[ok]))


def _scale(values: np.ndarray) -> float:
    span = float(np.max(values) - np.min(values))
    if span > 0.0:
        return span
    return max(abs(float(np.mean(values))), 1.0)


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
        Steady-state pre-run before each window (s), a multiple of ``sample_time``.
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


# One open twin per process, FMU path and content: worker processes (a pool's or a Dask cluster's)
# keep theirs across evaluations (trackingbox.analysis.executor.cached_model).


def _model(path: Path, tolerance: float = 1e-6) -> Any:
    from .analysis.executor import cached_model

    return cached_model(path, tolerance)


def _forget_models() -> None:
    """Pool initializer: a fresh worker owns no FMU yet."""
    from .analysis import executor

    with executor._LOCK:
        executor._MODELS.clear()


def close_models() -> None:
    """Close the twins this process has opened (estimation's and the analysis runs' cache)."""
    from .analysis.executor import clear_model_cache

    try:
        clear_model_cache()
    except Exception:  # noqa: BLE001 - closing is best effort
        log.debug("closing the cached twins failed", exc_info=True)


def window_setup(problem: Problem, window: WindowData, x: npt.ArrayLike
                 ) -> tuple[dict[str, float], float, np.ndarray, pd.DataFrame | None]:
    """What a run of the twin over *window* with parameter vector *x* starts from.

    Returns the parameter values (the fixed ones and *x*), the length of the
    held-input pre-run (the part of ``problem.warmup`` the window's lead-in does
    not cover, in whole sample times), the window's grid from its first sample,
    and the input table (inputs held at their first values over the pre-run).

    The run keeps the data's clock: the input table's times, and the model's
    ``time``, are seconds from the first sample of the data, so the run starts
    at :func:`run_start` (negative over the pre-run of a window at the first
    sample). A model whose equations use ``time`` (a drift or a fouling that
    diagnosis adds) then sees the same time on every window and in tracking.
    """
    values = np.asarray(x, dtype=float)
    parameters = dict(problem.fixed)
    parameters.update({name: float(v) for name, v in zip(problem.names, values)})
    t0 = run_start(problem, window)
    offset = float(window.time[0]) - t0
    grid = window.time - window.time[0]
    frame: dict[str, np.ndarray] = {"time": t0 + (np.concatenate(([0.0], offset + grid)) if offset > 0 else grid)}
    for name, series in window.inputs.items():
        frame[name] = np.concatenate(([series[0]], series)) if offset > 0 else series
    inputs = pd.DataFrame(frame) if window.inputs else None
    return parameters, offset, grid, inputs


def run_start(problem: Problem, window: WindowData) -> float:
    """Model time at which a run over *window* starts: its first grid time minus the held pre-run.

    Times are the data's clock (s from the first sample), see :func:`window_setup`.
    """
    lead_in = float(window.start - window.time[0])
    offset = max(0.0, problem.warmup - lead_in)
    offset = math.ceil(offset / problem.sample_time - 1e-9) * problem.sample_time
    return float(window.time[0]) - offset


def simulate_window(problem: Problem, window: WindowData, x: npt.ArrayLike,
                    tolerance: float = 1e-6) -> dict[str, np.ndarray]:
    """Simulate the twin over *window* with parameter vector *x*.

    Runs the held-input pre-run first (inputs held at their first values, for
    the part of ``problem.warmup`` the window's lead-in does not cover), then
    the lead-in and the window; returns output tag -> simulated values on the
    window's grid (lead-in included). *tolerance*: the solver's relative
    tolerance (tighter for finite differences that must resolve small changes).
    """
    parameters, offset, grid, inputs = window_setup(problem, window, x)
    t0 = run_start(problem, window)
    stop = t0 + offset + float(grid[-1])
    model = _model(problem.twin, tolerance)
    result = model.simulate(
        start_time=t0,
        stop_time=stop,
        output_interval=problem.sample_time,
        inputs=inputs,
        parameters=parameters,
        outputs=list(problem.outputs.values()),
    )
    t = np.asarray(result["time"], dtype=float)
    out: dict[str, np.ndarray] = {}
    for tag, name in problem.outputs.items():
        y = np.asarray(result[name], dtype=float)
        if not np.all(np.isfinite(y)):
            raise SimulationError(f"twin {problem.twin.name} gave non-finite values of {name!r}")
        out[tag] = np.interp(t0 + offset + grid, t, y)
    return out


class Objective:
    """The cost on one window: callable on a parameter vector, picklable.

    Parameters
    ----------
    problem
        The estimation problem.
    window
        The window whose measurements the simulation is compared with.
    """

    def __init__(self, problem: Problem, window: WindowData) -> None:
        self.problem = problem
        self.window = window
        tags = list(problem.outputs)
        self._valid = {tag: np.isfinite(window.measured[tag]) for tag in tags}
        self._scale = {tag: _scale(window.measured[tag][self._valid[tag]]) for tag in tags}
        n_tags = len(tags)
        self._weight = {
            tag: 1.0 / (self._scale[tag] * math.sqrt(self._valid[tag].sum() * n_tags)) for tag in tags
        }
        self._size = int(sum(v.sum() for v in self._valid.values()))

    def nrmse(self, x: npt.ArrayLike) -> dict[str, float]:
        """NRMSE per output tag at *x* (raises SimulationError if the twin fails)."""
        sim = simulate_window(self.problem, self.window, x)
        out = {}
        for tag, y in sim.items():
            ok = self._valid[tag]
            err = y[ok] - self.window.measured[tag][ok]
            out[tag] = float(np.sqrt(np.mean(err * err)) / self._scale[tag])
        return out

    def __call__(self, x: npt.ArrayLike) -> float:
        """Mean NRMSE over the output tags; :data:`FAILED_COST` if the simulation fails."""
        try:
            return float(np.mean(list(self.nrmse(x).values())))
        except (TrackingError, ArithmeticError) as exc:
            log.warning("simulation failed at %s: %s", _fmt(self.problem.names, x), exc)
            return FAILED_COST

    def residuals(self, x: npt.ArrayLike, tag_weights: Mapping[str, float] | None = None) -> np.ndarray:
        """Weighted residual vector; its sum of squares is the mean of NRMSE**2.

        With *tag_weights*, each tag's residuals are multiplied by the square root
        of its weight (the sum of squares becomes the weighted mean of NRMSE**2).
        """
        try:
            sim = simulate_window(self.problem, self.window, x)
        except (TrackingError, ArithmeticError) as exc:
            log.warning("simulation failed at %s: %s", _fmt(self.problem.names, x), exc)
            return np.full(self._size, FAILED_COST / math.sqrt(max(self._size, 1)))
        parts = []
        for tag, y in sim.items():
            ok = self._valid[tag]
            w = self._weight[tag] * (math.sqrt(tag_weights[tag]) if tag_weights else 1.0)
            parts.append((y[ok] - self.window.measured[tag][ok]) * w)
        return np.concatenate(parts)


def simulate_window_sensitivities(problem: Problem, window: WindowData, x: npt.ArrayLike
                                  ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """:func:`simulate_window` with the outputs' exact sensitivities w.r.t. the estimated parameters.

    One run of the twin with the forward sensitivity equations
    (:func:`trackingbox.sensitivity.simulate_sensitivities`, scaled by the bound
    ranges); returns output tag -> values and output tag -> ``d value / d x``
    (shape ``(len(grid), n_parameters)``) on the window's grid (lead-in included).
    """
    from .sensitivity import simulate_sensitivities

    parameters, offset, grid, inputs = window_setup(problem, window, x)
    t0 = run_start(problem, window)
    stop = t0 + offset + float(grid[-1])
    model = _model(problem.twin)
    run = simulate_sensitivities(model, wrt=problem.names, scales=problem.upper - problem.lower,
                                 start_time=t0, stop_time=stop, output_interval=problem.sample_time,
                                 inputs=inputs, parameters=parameters, outputs=list(problem.outputs.values()))
    at = t0 + offset + grid
    values: dict[str, np.ndarray] = {}
    slopes: dict[str, np.ndarray] = {}
    for tag, name in problem.outputs.items():
        values[tag] = np.interp(at, run.time, run.outputs[name])
        slopes[tag] = np.stack([np.interp(at, run.time, column) for column in run.sensitivities[name].T], axis=1)
    return values, slopes


def _residuals_and_jacobian(objective: Objective, x: npt.ArrayLike,
                            tag_weights: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Objective.residuals` and its exact Jacobian w.r.t. *x* from one sensitivity run.

    A failed run gives the failed residuals (as :meth:`Objective.residuals`) and a zero Jacobian.
    """
    problem = objective.problem
    try:
        sim, slopes = simulate_window_sensitivities(problem, objective.window, x)
    except (TrackingError, ArithmeticError) as exc:
        log.warning("sensitivity run failed at %s: %s", _fmt(problem.names, x), exc)
        size = objective._size
        return (np.full(size, FAILED_COST / math.sqrt(max(size, 1))), np.zeros((size, len(problem.names))))
    parts, rows = [], []
    for tag, y in sim.items():
        ok = objective._valid[tag]
        w = objective._weight[tag] * (math.sqrt(tag_weights[tag]) if tag_weights else 1.0)
        parts.append((y[ok] - objective.window.measured[tag][ok]) * w)
        rows.append(slopes[tag][ok] * w)
    return np.concatenate(parts), np.concatenate(rows, axis=0)


class _ExactResiduals:
    """Picklable ``x -> [residuals, Jacobian.ravel()]`` (one flat array, as the journal records it)."""

    def __init__(self, objective: Objective, weights: Mapping[str, float] | None) -> None:
        self.objective = objective
        self.weights = dict(weights) if weights else None

    def __call__(self, x: npt.ArrayLike) -> np.ndarray:
        r, jac = _residuals_and_jacobian(self.objective, x, self.weights)
        return np.concatenate([r, jac.ravel()])

    def split(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The residuals and the Jacobian back from :meth:`__call__`'s array."""
        size = self.objective._size
        return flat[:size], flat[size:].reshape(size, -1)


def _runs_native(model: Any) -> bool:
    """True if *model*'s runs go through the native stepper (what :meth:`FMUModel.stepper` chooses by default)."""
    import os

    if os.environ.get("TRACKINGBOX_NATIVE", "").strip() == "0":
        return False
    try:
        from .native import NativeUnavailable, native_reason
    except ImportError:  # pragma: no cover - the module is part of the package
        return False
    try:
        return native_reason(model) is None
    except NativeUnavailable:
        return False


def jacobian_support(problem: Problem, window: WindowData, requested: str) -> tuple[str, str]:
    """Which Jacobian the refinement uses: ``(method, reason)`` for the setting *requested*.

    ``"fd"`` gives ``("fd", "requested")``. ``"auto"`` gives ``("fd", why)`` when
    the twin's runs go through the native stepper (:mod:`trackingbox.native`:
    CVODE and the right-hand side in C), because the sensitivity equations run
    on the Python path (:class:`trackingbox.fmu.SensitivityStepper`) and the
    ``1 + n`` native runs were measured cheaper (``scripts/bench_jacobian --methods
    exact,fd,auto``, three refinement iterations from the start values,
    2026-11-27 on the 2-core machine at a load of 4-5 from other work: heat
    exchanger fd 19 runs 0.6 CPU s against exact 9 runs 2.5 CPU s, the same cost
    and estimate; heat production, 4 h, 14 parameters, fd 93 runs 8.6 CPU s
    against exact 9 runs 23.1 CPU s, training cost 0.1123 against 0.1111: fd
    costs a little accuracy there, ``jacobian="exact"`` keeps it).
    Otherwise ``"exact"`` and ``"auto"`` check the twin
    (:func:`trackingbox.sensitivity.support`, at the start of a run over
    *window* with the start values): ``("exact", "")`` when it provides usable
    directional derivatives; otherwise ``"auto"`` falls back to ``("fd", why)``
    and ``"exact"`` raises :class:`~trackingbox.errors.EstimationError` saying why.
    ``"prefer-exact"`` skips the native check: exact where the twin supports it,
    else ``("fd", why)``.
    """
    from .sensitivity import support

    if requested not in JACOBIAN_METHODS:
        raise EstimationError(f"jacobian must be one of {', '.join(JACOBIAN_METHODS)}, not {requested!r}")
    if requested == "fd":
        return "fd", "requested"
    model = _model(problem.twin)
    if requested == "auto" and _runs_native(model):
        why = (f"{Path(problem.twin).name} runs on the native stepper, the sensitivity equations do not: "
               "1 + n native runs are the cheaper Jacobian")
        log.info("refinement Jacobian by finite differences: %s", why)
        return "fd", why
    parameters, _, _, inputs = window_setup(problem, window, problem.start)
    found = support(model, problem.names, problem.upper - problem.lower, start_time=run_start(problem, window),
                    parameters=parameters, inputs=inputs)
    if found.exact:
        return "exact", ""
    if requested == "exact":
        raise EstimationError(f"jacobian = 'exact' is not possible: {found.reason}; use 'fd' or 'auto'")
    log.info("refinement Jacobian by finite differences: %s", found.reason)
    return "fd", found.reason


class _Residuals:
    """Picklable ``x -> Objective.residuals(x, weights)`` for a worker pool."""

    def __init__(self, objective: Objective, weights: Mapping[str, float] | None) -> None:
        self.objective = objective
        self.weights = dict(weights) if weights else None

    def __call__(self, x: npt.ArrayLike) -> np.ndarray:
        return self.objective.residuals(x, self.weights)


def jacobian_points(x: npt.ArrayLike, lower: npt.ArrayLike, upper: npt.ArrayLike,
                    step: float = DIFF_STEP) -> tuple[np.ndarray, np.ndarray]:
    """Perturbed points and signed steps of a forward-difference Jacobian inside the bounds.

    Parameter ``j`` moves by ``step * (upper_j - lower_j)``, backwards where a
    forward step would leave the bounds.

    >>> pts, h = jacobian_points([0.0, 1.0], [0.0, 0.0], [1.0, 1.0], step=0.1)
    >>> pts.tolist(), h.tolist()
    ([[0.1, 1.0], [0.0, 0.9]], [0.1, -0.1])
    """
    x = np.asarray(x, dtype=float)
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    h = step * (hi - lo)
    h = np.where(x + h > hi, -h, h)
    points = np.repeat(x[None, :], len(x), axis=0)
    points[np.arange(len(x)), np.arange(len(x))] += h
    return points, h


def _fmt(names: Sequence[str], x: npt.ArrayLike) -> str:
    return ", ".join(f"{n}={v:.6g}" for n, v in zip(names, np.atleast_1d(np.asarray(x, dtype=float))))


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


def load_windows(spec: Spec, *, warmup: float | None = None) -> tuple[WindowData, WindowData]:
    """Cut the training and validation windows out of the spec's measurement view.

    Each window is a :class:`~trackingbox.data.MeasurementView` (same grid,
    gap rule, stoppage mask and scored samples as tracking and validation).
    A window that starts after the first sample gets a *lead-in*: up to
    ``warmup`` seconds of the measured inputs before it (never across an input
    gap), simulated but not part of the cost, so the twin's slow states follow
    the real history into the window. The rest of the warm-up is the held-input
    pre-run (:func:`simulate_window`).

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
    from .data import MeasurementView

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
            view = MeasurementView.from_spec(spec, name, lead=lead_s)
        except DataError as exc:
            raise DataError(f"{name} window: {exc}; estimation needs at least {MIN_VALID_SAMPLES} samples") \
                from None
        grid = view.grid
        n_lead = view.lead
        n_window = grid.size - n_lead
        # the lead-in starts after the last input gap before the window
        cut = 0
        for tag in spec.inputs:
            bad_lead = np.flatnonzero(~np.isfinite(view.values(tag)[:n_lead]))
            if bad_lead.size:
                cut = max(cut, int(bad_lead[-1]) + 1)
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
    from .fmu import read_info

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
    if problems:
        raise SpecError("; ".join(problems))
    dt = float(spec.sample_time)
    w = DEFAULT_WARMUP if warmup is None else float(warmup)
    if w < 0:
        raise EstimationError(f"warm-up must be >= 0 s, got {w:g}")
    w = math.ceil(w / dt - 1e-9) * dt
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
    )


# --------------------------------------------------------------------------- the estimation


def _write_checkpoint(path: Path | None, payload: dict[str, Any]) -> None:
    if path is not None:
        write_text_atomic(path, json.dumps(payload, indent=2) + "\n")


def estimate(
    spec: Any,
    *,
    seed: int = 0,
    workers: int | None = None,
    maxiter: int | None = None,
    popsize: int | None = None,
    warmup: float | None = None,
    refine: bool = True,
    refine_iterations: int = MAX_REFINE_ITERATIONS,
    progress: ProgressCallback | None = None,
    checkpoint: str | Path | None = None,
    global_grid: float | None = None,
    resume: bool = False,
    refine_grid: float | None = None,
    jacobian: str = "auto",
    scheduler: str | None = None,
    settle: float = GLOBAL_SETTLE,
    level: float | None = 0.95,
    identify: bool = True,
) -> EstimationResult:
    """Estimate the spec's ``[[parameters]]`` on its training window.

    Parameters
    ----------
    spec
        A loaded spec (:func:`trackingbox.spec.load_spec`).
    seed
        Seed of the global search: the same seed gives the same result.
    workers
        Processes evaluating the population and the finite-difference Jacobian
        columns in parallel (``None`` or 1: in this process). Each worker opens
        the twin once.
    maxiter
        Generations of differential evolution (0: only the start values and the
        refinement); default :func:`default_maxiter`.
    popsize
        Population size per parameter (population = ``popsize * n_parameters``, at least 5);
        default ``max(2, ceil(DEFAULT_POPULATION / n_parameters))``.
    warmup
        Steady-state pre-run before each window (s); default :data:`DEFAULT_WARMUP`.
    refine
        Run the least-squares refinement after the global search.
    refine_iterations
        Most least-squares iterations; each costs ``1 + n_parameters`` simulations
        (finite-difference Jacobian).
    progress
        Called as ``progress(stage, iteration, total, best_cost)``.
    checkpoint
        If given, the best point so far is written there as JSON after every
        generation and refinement step (atomically), so an interrupted run keeps what it found.
        Beside it, ``<checkpoint stem>.journal`` records every evaluation
        (:class:`trackingbox.checkpoint.Journal`), so that *resume* continues.
    global_grid
        Grid step (s) of the global search's cost; default :data:`DEFAULT_GLOBAL_GRID`
        (``sample_time`` or less: the full grid).
    resume
        Continue an interrupted run from the journal beside *checkpoint*: the
        search is run again with the recorded evaluations served from the
        journal (no simulation is repeated), so it takes the same path and the
        result is bit-identical to an uninterrupted run's. A journal of another
        spec, data, twin or settings, or a corrupt one, is refused
        (:class:`~trackingbox.errors.CheckpointError`).
    refine_grid
        Grid step (s) of the refinement's cost, built as the global search's
        (:func:`coarsen`); default: the full grid. A run costs about in proportion
        to its grid points, so a coarse grid makes the refinement several times
        cheaper; the result and its cost are then reported on the full grid (and the
        refinement is dropped if it is worse there than where it started).
    jacobian
        The refinement's Jacobian: ``"exact"`` (forward sensitivity equations
        from the twin's directional derivatives: one run per evaluation gives the
        residuals and their Jacobian; :class:`~trackingbox.errors.EstimationError`
        if the twin cannot), ``"fd"`` (forward differences: ``1 + n`` runs) or
        ``"auto"`` (fd where the twin's runs are native, measured cheaper than
        the Python-path sensitivity run; else exact where the twin supports it,
        else fd: :func:`jacobian_support`) or ``"prefer-exact"`` (exact where the
        twin supports it, else fd). What was used, and why not exact, is
        in the result's ``refinement``.
    scheduler
        Run the parallel evaluations on a Dask cluster instead of local processes:
        ``"local"`` (a local cluster of *workers* processes) or a scheduler's
        address (``tcp://host:8786``); see
        :func:`trackingbox.analysis.executor.make_executor`. The result is the same
        as with local worker processes (the same points, evaluated elsewhere).
    settle
        Stop the global search once the better half of its population lies within
        this fraction of every parameter's range (default :data:`GLOBAL_SETTLE`);
        0: run every generation.
    level
        Confidence level of the intervals at the estimate
        (:func:`trackingbox.identify.intervals.uncertainty`); None: no intervals.
    identify
        Check what the data can determine at the start values before the search and
        warn about parameters they cannot tell apart (:mod:`trackingbox.identify`).

    Returns
    -------
    EstimationResult

    Raises
    ------
    SpecError, DataError, FMUError, EstimationError, CheckpointError
    """
    if resume and checkpoint is None:
        raise EstimationError("resume needs a checkpoint (trackingbox estimate --resume needs --report DIR)")
    _check_settings(spec, seed=seed, workers=workers, maxiter=maxiter, popsize=popsize, warmup=warmup,
                    refine_iterations=refine_iterations, global_grid=global_grid)
    if not (isinstance(settle, (int, float)) and not isinstance(settle, bool) and 0.0 <= settle < 1.0):
        raise EstimationError(f"estimate: settle must be a fraction in [0, 1), not {settle!r}")
    if jacobian not in JACOBIAN_METHODS:
        raise EstimationError(f"estimate: jacobian must be one of {', '.join(JACOBIAN_METHODS)}, "
                              f"not {jacobian!r}")
    if maxiter is None:
        maxiter = default_maxiter(len(list(spec.parameters)), popsize)
    from .identify import hooks as identify_hooks  # identifiability before, intervals after

    if level is not None and not (isinstance(level, (int, float)) and 0.0 < float(level) < 1.0):
        raise EstimationError(f"estimate: level must be a fraction in (0, 1), not {level!r}")
    try:
        before = identify_hooks.before_estimate(spec, warmup=warmup, jacobian=jacobian) if identify else None
        result = _estimate(spec, seed=seed, workers=workers, maxiter=maxiter, popsize=popsize, warmup=warmup,
                           refine=refine, refine_iterations=refine_iterations, progress=progress,
                           checkpoint=checkpoint, global_grid=global_grid, resume=resume,
                           refine_grid=refine_grid, jacobian=jacobian, scheduler=scheduler,
                           settle=float(settle))
        return identify_hooks.after_estimate(spec, result, before, level=level, warmup=warmup, jacobian=jacobian)
    finally:
        close_models()


#: most samples one simulated window may have (warm-up included): above it the run is refused
MAX_WINDOW_SAMPLES = 5_000_000
#: most simulations the global search may be asked for
MAX_GLOBAL_EVALUATIONS = 1_000_000


def _check_settings(spec: Any, *, seed: int, workers: int | None, maxiter: int | None, popsize: int | None,
                    warmup: float | None, refine_iterations: int, global_grid: float | None) -> None:
    """Refuse settings out of range before any work (every problem at once), naming the setting."""
    problems: list[str] = []

    def integer(name: str, value: Any, low: int) -> None:
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                                  or value < low):
            problems.append(f"{name} must be an integer >= {low}, got {value!r}")

    integer("seed", seed, 0)
    integer("workers", workers, 1)
    integer("maxiter", maxiter, 0)
    integer("popsize", popsize, 1)
    integer("refine_iterations", refine_iterations, 0)
    if warmup is not None and not (isinstance(warmup, (int, float)) and math.isfinite(warmup) and warmup >= 0):
        problems.append(f"warmup must be a finite number of seconds >= 0, got {warmup!r}")
    if global_grid is not None and not (isinstance(global_grid, (int, float)) and math.isfinite(global_grid)
                                        and global_grid > 0):
        problems.append(f"global_grid must be a finite number of seconds > 0, got {global_grid!r}")
    if not list(spec.parameters):
        problems.append(f"{spec.path} has no [[parameters]]: there is nothing to estimate")
    windows = getattr(spec, "windows", {}) or {}
    span = max((b - a for a, b in windows.values()), default=0.0)
    if not problems and global_grid is not None and span > 0 and global_grid > span:
        problems.append(f"global_grid = {global_grid:g} s is longer than the windows of {spec.path.name} "
                        f"(the longest spans {span:g} s)")
    if not problems and maxiter is not None:
        n = len(list(spec.parameters))
        evaluations = (maxiter + 1) * _population(n, popsize) * n
        if evaluations > MAX_GLOBAL_EVALUATIONS:
            problems.append(f"maxiter = {maxiter} and popsize = {popsize} ({_population(n, popsize) * n} individuals) "
                            f"ask for up to {evaluations:.3g} simulations (at most {MAX_GLOBAL_EVALUATIONS:g})")
    if not problems and warmup is not None and spec.sample_time > 0:
        samples = (float(warmup) + span) / float(spec.sample_time)
        if samples > MAX_WINDOW_SAMPLES:
            problems.append(f"warmup = {warmup:g} s: a window and its warm-up would take {samples:.3g} samples "
                            f"of sample_time = {spec.sample_time:g} s (at most {MAX_WINDOW_SAMPLES:g})")
    if problems:
        raise EstimationError("estimate: " + "; ".join(problems))


def default_maxiter(n_parameters: int, popsize: int | None = None) -> int:
    """Default number of generations: :data:`DEFAULT_MAXITER`, capped by the simulation budget.

    With ``P`` individuals in all, at most ``DEFAULT_GLOBAL_EVALUATIONS // P - 1``
    generations (at least 2): 30 for one parameter (population 15), 16 for
    fourteen (population 28).

    >>> default_maxiter(1), default_maxiter(14)
    (30, 16)
    """
    population = _population(n_parameters, popsize) * n_parameters
    return max(2, min(DEFAULT_MAXITER, DEFAULT_GLOBAL_EVALUATIONS // population - 1))


def _population(n: int, popsize: int | None) -> int:
    """Population per parameter handed to differential evolution (total at least 5)."""
    return max(popsize or max(2, math.ceil(DEFAULT_POPULATION / n)), math.ceil(5 / n))


def _global_search(train: Objective, coarse: Objective, problem: Problem, pool: Any, journal: Journal, *, seed: int,
                   maxiter: int, popsize: int | None, start_cost: float, history: list[float],
                   best: tuple[np.ndarray, float], progress: ProgressCallback | None,
                   checkpoint: Callable[[int, np.ndarray, float, int], None],
                   settle: float = GLOBAL_SETTLE) -> tuple[np.ndarray, float, int]:
    """Differential evolution on the *coarse* cost; returns best x, its *train* cost, evaluations.

    The first population is a Latin hypercube with the start values in it. After
    each generation the population's best point is scored once on the full grid
    (*train*), so the best-so-far and the history are in the cost the report uses.
    The search stops early once the better half of the population lies within
    *settle* of each parameter's bound range (:data:`GLOBAL_SETTLE`; 0: never).
    Every evaluation goes through *journal* (served from it when recorded).
    """
    from scipy.optimize import differential_evolution

    n = len(problem.names)
    best_x, best_cost = best
    per_parameter = _population(n, popsize)
    generation = 0
    scored: list[np.ndarray] = []
    span = problem.upper - problem.lower
    settled = False

    def on_generation(intermediate_result: Any) -> None:
        nonlocal generation, best_x, best_cost, settled
        generation += 1
        x = np.array(intermediate_result.x, dtype=float)
        if coarse is train:
            cost = float(intermediate_result.fun)
        elif scored and np.array_equal(scored[-1], x):
            cost = math.inf  # already scored
        else:
            scored.append(x)
            cost = journal.call("train", train, x)
        if cost < best_cost:
            best_x, best_cost = x, cost
        history.append(best_cost)
        checkpoint(generation, best_x, best_cost, (generation + 1) * per_parameter * n + len(scored))
        if progress is not None:
            progress("global", generation, maxiter, best_cost)
        if settle > 0:
            extent = _better_half_extent(intermediate_result, span)
            log.debug("generation %d: better half of the population within %.3g of the ranges", generation, extent)
            if extent <= settle:
                settled = True
                log.info("global search settled after %d generations: the better half of its population lies "
                         "within %.3g of every parameter's range; the refinement goes on from its best point",
                         generation, extent)
                raise StopIteration

    def func(x: np.ndarray) -> float:
        return journal.call("coarse", coarse, x)

    def mapper(f: Callable[[Any], Any], xs: Any) -> list[Any]:
        return journal.map("coarse", f, xs, pool.map)

    de = differential_evolution(
        coarse if pool is not None else func,
        list(zip(problem.lower, problem.upper)),
        maxiter=maxiter,
        popsize=per_parameter,
        rng=seed,
        polish=False,
        init="latinhypercube" if n > 1 else "random",
        x0=problem.start if start_cost < FAILED_COST else None,
        updating="deferred" if pool is not None else "immediate",
        workers=mapper if pool is not None else 1,
        callback=on_generation,
        tol=1e-3,
    )
    x = np.array(de.x, dtype=float)
    if coarse is train and de.fun < best_cost:
        best_x, best_cost = x, float(de.fun)
    elif coarse is not train and not any(np.array_equal(x, y) for y in scored):
        scored.append(x)
        cost = journal.call("train", train, x)
        if cost < best_cost:
            best_x, best_cost = x, cost
    log.info("global search: %d generations%s, %d evaluations (+%d on the full grid), cost %.6g (%s)",
             de.nit, " (settled)" if settled else "", de.nfev, len(scored), best_cost, _fmt(problem.names, best_x))
    return best_x, best_cost, int(de.nfev) + len(scored)


def _better_half_extent(intermediate_result: Any, span: np.ndarray) -> float:
    """Largest extent, over the parameters, of the better half of a DE population, in parts of the ranges."""
    population = np.asarray(getattr(intermediate_result, "population", ()), dtype=float)
    energies = np.asarray(getattr(intermediate_result, "population_energies", ()), dtype=float)
    if population.ndim != 2 or population.shape[0] != energies.size or energies.size < 2:
        return math.inf
    better = population[np.argsort(energies, kind="stable")[:max(2, energies.size // 2)]]
    return float(np.max((better.max(axis=0) - better.min(axis=0)) / span))


def _refine(train: Objective, problem: Problem, pool: Any, journal: Journal, *, best: tuple[np.ndarray, float], iterations: int,
            progress: ProgressCallback | None, label: str = "",
            checkpoint: Callable[[int, np.ndarray, float, int], None],
            jacobian: str = "fd") -> tuple[np.ndarray, float, int]:
    """Bounded least squares (trust-region reflective) from *best*; returns best x, cost, evaluations.

    With *jacobian* ``"fd"`` the Jacobian is a forward difference on all parameters
    (:func:`jacobian_points`), its ``n`` simulations spread over *pool*; with
    ``"exact"`` every residual evaluation is a sensitivity run that also gives the
    Jacobian (:func:`_exact_functions`). With several output tags a second pass
    reweights each tag by ``1 / NRMSE_tag`` at the first pass's point (iteratively
    reweighted least squares), which makes the weighted mean of ``NRMSE**2`` agree with
    the mean NRMSE there in value and gradient. A pass's point is kept only if its mean
    NRMSE is not above the best so far.
    """
    from scipy.optimize import least_squares

    best_x, best_cost = best
    n = len(problem.names)
    evaluations = 0
    passes = 2 if len(problem.outputs) > 1 else 1
    total = passes * iterations * (1 if jacobian == "exact" else n + 1)
    span = problem.upper - problem.lower
    for k in range(passes):
        weights: dict[str, float] | None = None
        if k > 0:
            try:
                per_tag = journal.call(label + "nrmse", train.nrmse, best_x)
            except TrackingError as exc:
                log.warning("no reweighted refinement: the twin failed at the estimate (%s)", exc)
                break
            evaluations += 1
            mean_nrmse = float(np.mean(list(per_tag.values())))
            weights = {tag: mean_nrmse / max(v, 1e-3 * mean_nrmse) for tag, v in per_tag.items()}
        task = _Residuals(train, weights)
        last: dict[str, Any] = {"x": None, "r": None, "best": math.inf}

        def record(x: np.ndarray, r: np.ndarray) -> None:
            nonlocal evaluations
            evaluations += 1
            rms = float(np.sqrt(np.sum(r * r)))
            if rms < last["best"]:
                last["best"] = rms
                checkpoint(evaluations, x, rms, evaluations)
            if progress is not None:
                progress("refine", evaluations, total, rms)

        def fd_fun(x: np.ndarray) -> np.ndarray:
            r = journal.call(label + f"residuals{k}", task, x)
            last["x"], last["r"] = np.array(x, dtype=float), r
            record(x, r)
            return r

        if jacobian == "exact":
            fun, jac = _exact_functions(_ExactResiduals(train, weights), journal, label + f"exact{k}", record)
        else:
            fun = fd_fun
            jac = _fd_jacobian(fun, last, task, problem, pool, journal, label + f"residuals{k}", record)
        jac, stop = _step_stop(jac, problem)
        try:
            ls = least_squares(fun, np.clip(best_x, problem.lower, problem.upper), jac=jac,
                               bounds=(problem.lower, problem.upper), x_scale=span, method="trf",
                               max_nfev=max(1, int(iterations)), ftol=1e-6, xtol=1e-6, callback=stop)
        except (ValueError, np.linalg.LinAlgError) as exc:
            log.warning("refinement pass %d failed (%s); keeping the estimate so far", k + 1, exc)
            continue
        refined = np.clip(np.asarray(ls.x, dtype=float), problem.lower, problem.upper)
        refined_cost = journal.call(label + "train", train, refined)
        evaluations += 1
        log.info("refinement pass %d: %d iterations, cost %.6g -> %.6g", k + 1, ls.nfev, best_cost, refined_cost)
        if refined_cost <= best_cost:
            best_x, best_cost = refined, refined_cost
    return best_x, best_cost, evaluations


def _step_stop(jac: Callable[[np.ndarray], np.ndarray], problem: Problem
               ) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[Any], None]]:
    """*jac* remembering its last point, and a least-squares callback applying :data:`REFINE_STEP_TOLERANCE`.

    After each iteration the callback takes the Gauss-Newton step from the
    Jacobian at the accepted point and its residuals, projects it on the bounds,
    and stops the refinement (``StopIteration``) when no parameter would move by
    more than :data:`REFINE_STEP_TOLERANCE` of its bound range.
    """
    kept: dict[str, Any] = {"x": None, "jac": None}
    span = problem.upper - problem.lower

    def remembering(x: np.ndarray) -> np.ndarray:
        out = jac(x)
        kept["x"], kept["jac"] = np.array(x, dtype=float), np.asarray(out, dtype=float)
        return out

    def stop(intermediate_result: Any) -> None:
        x = np.asarray(intermediate_result.x, dtype=float)
        if kept["x"] is None or not np.array_equal(kept["x"], x):
            return
        r = np.asarray(intermediate_result.fun, dtype=float)
        try:
            step = np.linalg.lstsq(kept["jac"], -r, rcond=None)[0]
        except np.linalg.LinAlgError:
            return
        moved = np.clip(x + step, problem.lower, problem.upper) - x
        if np.all(np.isfinite(moved)) and np.max(np.abs(moved) / span) < REFINE_STEP_TOLERANCE:
            log.debug("refinement: next Gauss-Newton step %s below %g of the ranges: stop",
                      _fmt(problem.names, moved), REFINE_STEP_TOLERANCE)
            raise StopIteration

    return remembering, stop


def _fd_jacobian(fun: Callable[[np.ndarray], np.ndarray], last: dict[str, Any], task: _Residuals, problem: Problem,
                 pool: Any, journal: Journal, label: str, record: Callable[[np.ndarray, np.ndarray], None]
                 ) -> Callable[[np.ndarray], np.ndarray]:
    """The refinement's forward-difference Jacobian: ``n`` perturbed runs over *pool* (:func:`jacobian_points`)."""

    def jac(x: np.ndarray) -> np.ndarray:
        if last["x"] is not None and np.array_equal(last["x"], x):
            r0 = last["r"]
        else:
            r0 = fun(x)
        points, h = jacobian_points(x, problem.lower, problem.upper)
        rows = journal.map(label, task, list(points), pool.map if pool is not None else None)
        for p, r in zip(points, rows):
            record(p, r)
        return np.stack([(r - r0) / hj for r, hj in zip(rows, h)], axis=1)

    return jac


def _exact_functions(task: _ExactResiduals, journal: Journal, label: str,
                     record: Callable[[np.ndarray, np.ndarray], None]
                     ) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]:
    """``fun, jac`` for least squares from sensitivity runs: each ``fun`` run keeps its Jacobian for ``jac``.

    Trust-region reflective asks for the Jacobian only at the point it last
    evaluated and accepted, so ``jac`` is served from that run; a point not run
    yet is run first.
    """
    kept: dict[str, Any] = {"x": None, "jac": None}

    def fun(x: np.ndarray) -> np.ndarray:
        r, jac = task.split(journal.call(label, task, x))
        kept["x"], kept["jac"] = np.array(x, dtype=float), jac
        record(x, r)
        return r

    def jac(x: np.ndarray) -> np.ndarray:
        if kept["x"] is None or not np.array_equal(kept["x"], x):
            fun(x)
        return kept["jac"]

    return fun, jac


def _estimate(spec: Any, *, seed: int, workers: int | None, maxiter: int, popsize: int | None,
              warmup: float | None,
              refine: bool, refine_iterations: int, progress: ProgressCallback | None,
              checkpoint: str | Path | None, global_grid: float | None, resume: bool = False,
              refine_grid: float | None = None, jacobian: str = "auto",
              scheduler: str | None = None, settle: float = GLOBAL_SETTLE) -> EstimationResult:
    t_start = time.perf_counter()
    ckpt = Path(checkpoint) if checkpoint is not None else None
    problem = problem_from_spec(spec, warmup=warmup)
    journal = Journal(journal_path(ckpt) if ckpt is not None else None,
                      _identity(spec, problem, seed=seed, maxiter=maxiter, popsize=popsize, refine=refine,
                                refine_iterations=refine_iterations, global_grid=global_grid,
                                refine_grid=refine_grid, parallel=_parallel(workers, scheduler),
                                **({} if jacobian == "fd" else {"jacobian": jacobian}),
                                **({} if settle == 0 else {"settle": settle})), resume=resume)
    try:
        return _run(spec, problem, journal, t_start=t_start, ckpt=ckpt, seed=seed, workers=workers,
                    maxiter=maxiter, popsize=popsize, refine=refine, refine_iterations=refine_iterations,
                    progress=progress, global_grid=global_grid, refine_grid=refine_grid, jacobian=jacobian,
                    scheduler=scheduler, settle=settle)
    finally:
        if resume:
            log.info("%d evaluations served from the journal %s", journal.served, journal.path)
        journal.close()


def _parallel(workers: int | None, scheduler: str | None) -> bool:
    """Whether the evaluations go to an executor (then differential evolution updates generation-wise)."""
    return scheduler is not None or int(workers or 1) > 1


def _open_pool(workers: int | None, scheduler: str | None) -> Any:
    """The executor of the population and the fd Jacobian columns; ``None``: evaluate in this process.

    Local worker processes (*workers* > 1; spawned, so that their CPU time counts
    as this process's children's, which diagnosis reports) or a Dask cluster
    (*scheduler*), from :func:`trackingbox.analysis.executor.make_executor`: its
    ``map`` keeps the order of the points, so the search takes the same path on either.
    """
    if not _parallel(workers, scheduler):
        return None
    from .analysis.executor import make_executor

    return make_executor(scheduler, workers if workers is not None or scheduler else 1, start_method="spawn")


def _close_pool(pool: Any, *, failed: bool = False) -> None:
    """Shut the executor down; after a failure or an interrupt without waiting for running evaluations."""
    if pool is not None:
        from .analysis.executor import stop_executor

        stop_executor(pool, wait=not failed)


def journal_path(checkpoint: str | Path) -> Path:
    """The evaluation journal kept beside an estimation checkpoint (``checkpoint.journal``)."""
    return Path(checkpoint).with_suffix(".journal")


def _identity(spec: Any, problem: Problem, **settings: Any) -> dict[str, Any]:
    """What makes two estimation runs the same search: the inputs' bytes and the settings."""
    from .checkpoint import file_digest

    files = {"spec": spec.path, "measurements": spec.measurements, "twin": problem.twin}
    return {**{name: file_digest(path) for name, path in files.items()},
            "parameters": list(problem.names), "lower": [float(v).hex() for v in problem.lower],
            "upper": [float(v).hex() for v in problem.upper], "start": [float(v).hex() for v in problem.start],
            "warmup": float(problem.warmup), **settings}


def _run(spec: Any, problem: Problem, journal: Journal, *, t_start: float, ckpt: Path | None, seed: int,
         workers: int | None, maxiter: int, popsize: int | None, refine: bool, refine_iterations: int,
         progress: ProgressCallback | None, global_grid: float | None,
         refine_grid: float | None = None, jacobian: str = "auto",
         scheduler: str | None = None, settle: float = GLOBAL_SETTLE) -> EstimationResult:
    training, validation = load_windows(spec, warmup=problem.warmup)
    train = Objective(problem, training)
    valid = Objective(problem, validation)
    history: list[float] = []
    evaluations = 0
    refinement: dict[str, Any] = {}

    start_cost = journal.call("train", train, problem.start)
    evaluations += 1
    if start_cost >= FAILED_COST:
        log.warning("the twin fails at the start values; the global search starts without them")
    best_x, best_cost = problem.start.copy(), start_cost
    history.append(start_cost)
    log.info("start values: cost %.6g (%s)", start_cost, _fmt(problem.names, best_x))

    pool = _open_pool(workers, scheduler) if maxiter > 0 or refine else None
    try:
        if maxiter > 0:
            stride = max(1, int(math.floor((global_grid or DEFAULT_GLOBAL_GRID) / problem.sample_time + 1e-9)))
            coarse = train
            if stride > 1:
                coarse = Objective(replace(problem, sample_time=problem.sample_time * stride),
                                   coarsen(training, stride))
            best_x, best_cost, n_global = _global_search(
                train, coarse, problem, pool, journal, seed=seed, maxiter=maxiter, popsize=popsize,
                start_cost=start_cost, settle=settle,
                history=history, best=(best_x, best_cost), progress=progress,
                checkpoint=lambda g, x, c, e: _write_checkpoint(ckpt, {
                    "stage": "global", "iteration": g, "best_cost": c,
                    "parameters": dict(zip(problem.names, map(float, x))), "evaluations": evaluations + e,
                    "seconds": time.perf_counter() - t_start, "history": history}))
            evaluations += n_global
        if refine:
            fine, refine_cost = train, best_cost
            stride = max(1, int(math.floor((refine_grid or problem.sample_time) / problem.sample_time + 1e-9)))
            if stride > 1:
                fine = Objective(replace(problem, sample_time=problem.sample_time * stride),
                                 coarsen(training, stride))
                refine_cost = journal.call(f"coarse{stride}", fine, best_x)
                evaluations += 1
            method, reason = jacobian_support(problem, fine.window, jacobian)
            wall0, cpu0 = time.perf_counter(), time.process_time()
            refined_x, refined_cost, n_local = _refine(
                fine, problem, pool, journal, best=(best_x, refine_cost), iterations=refine_iterations,
                label="" if stride == 1 else f"coarse{stride}:",
                progress=progress,
                checkpoint=lambda k, x, c, e: _write_checkpoint(ckpt, {
                    "stage": "refine", "iteration": k, "best_cost": best_cost,
                    "parameters": dict(zip(problem.names, map(float, best_x))),
                    "refine_rms_nrmse": c, "refine_parameters": dict(zip(problem.names, map(float, x))),
                    "evaluations": evaluations + e, "seconds": time.perf_counter() - t_start,
                    "history": history}),
                jacobian=method)
            evaluations += n_local
            refinement = {"jacobian": method, "requested": jacobian, "reason": reason, "runs": n_local,
                          "seconds": time.perf_counter() - wall0, "cpu_seconds": time.process_time() - cpu0}
            log.info("refinement: %s Jacobian%s, %d runs, %.3g s", method, f" ({reason})" if reason else "",
                     n_local, refinement["seconds"])
            if stride == 1:
                best_x, best_cost = refined_x, refined_cost
            elif not np.array_equal(refined_x, best_x):
                full_cost = journal.call("train", train, refined_x)  # back on the full grid
                evaluations += 1
                if full_cost <= best_cost:
                    best_x, best_cost = refined_x, full_cost
            history.append(best_cost)
            if progress is not None:
                progress("local", 1, 1, best_cost)
    except BaseException:
        _close_pool(pool, failed=True)
        raise
    _close_pool(pool)

    if best_cost >= FAILED_COST:
        raise EstimationError(
            f"the twin {problem.twin.name} could not be simulated on the training window for any "
            f"parameter set tried ({evaluations} evaluations)"
        )
    try:
        training_nrmse = train.nrmse(best_x)
        validation_nrmse = valid.nrmse(best_x)
        validation_initial = valid.nrmse(problem.start)
    except SimulationError as exc:
        raise EstimationError(f"validation simulation failed: {exc}") from exc
    seconds = time.perf_counter() - t_start
    result = EstimationResult(
        parameters={name: float(v) for name, v in zip(problem.names, best_x)},
        training_nrmse=training_nrmse,
        validation_nrmse=validation_nrmse,
        validation_nrmse_initial=validation_initial,
        evaluations=evaluations,
        seconds=seconds,
        history=tuple(history),
        initial={name: float(v) for name, v in zip(problem.names, problem.start)},
        bounds={name: (float(lo), float(hi)) for name, lo, hi in zip(problem.names, problem.lower, problem.upper)},
        warmup=problem.warmup,
        refinement=refinement,
    )
    _write_checkpoint(ckpt, {"stage": "done", **result.to_json(), "history": list(result.history)})
    return result


def fit_series(spec: Any, parameter_sets: Mapping[str, Mapping[str, float]], *,
               warmup: float | None = None) -> dict[str, pd.DataFrame]:
    """Measured and simulated series per window for fit plots.

    Parameters
    ----------
    spec
        A loaded spec.
    parameter_sets
        Label -> parameter values (missing names take their start values).
    warmup
        As in :func:`estimate`.

    Returns
    -------
    dict
        ``"training"`` / ``"validation"`` -> DataFrame with ``time`` and, per output
        tag, ``<tag>`` (measured, NaN where excluded) and ``<tag>:<label>`` (simulated).
    """
    problem = problem_from_spec(spec, warmup=warmup)
    out = {}
    try:
        windows = load_windows(spec, warmup=problem.warmup)
        for window in windows:
            out[window.name] = _series(problem, window, parameter_sets)
    finally:
        close_models()
    return out


def _series(problem: Problem, window: WindowData,
            parameter_sets: Mapping[str, Mapping[str, float]]) -> pd.DataFrame:
    """Measured and simulated series of one window (lead-in left out)."""
    keep = slice(window.lead, None)
    frame: dict[str, np.ndarray] = {"time": window.time[keep]}
    for tag in problem.outputs:
        frame[tag] = window.measured[tag][keep]
    for label, values in parameter_sets.items():
        x = np.array([float(values.get(n, s)) for n, s in zip(problem.names, problem.start)])
        sim = simulate_window(problem, window, x)
        for tag, y in sim.items():
            frame[f"{tag}:{label}"] = y[keep]
    return pd.DataFrame(frame)


# --------------------------------------------------------------------------- writing back

def write_starts(path: str | Path, values: Mapping[str, float],
                 intervals: Mapping[str, tuple[float, float]] | None = None) -> Any:
    """Write *values* as the ``start`` of the spec file's ``[[parameters]]``, atomically.

    Delegates to :func:`trackingbox.spec.write_starts` (one writer for the spec,
    keeping comments and layout); kept here for existing callers. *intervals*: their
    confidence intervals (``interval = [a, b]``, where determined).
    """
    from .spec import write_starts as _write_starts

    return _write_starts(path, values, intervals)
