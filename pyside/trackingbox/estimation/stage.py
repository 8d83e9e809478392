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
simulation therefore begins up to ``warmup`` seconds (default :data:`DEFAULT_WARMUP`)
before its window, with the candidate parameters applied, and runs through the
measured history there (*lead-in*, measured inputs, never scored), so slow states
follow the history into the window. No FMU runs before the data's first sample:
where the data have less history (a window at the first sample has none) the
warm-up is shortened to what exists, the result says so
(:attr:`EstimationResult.warmups`, :meth:`EstimationResult.warmup_note`), and the
run starts there from the FMU's own initial state, or from its steady state with
the inputs there when the spec says ``[data] initial = "steady"`` (model exchange;
an integrating state without a steady state is refused, naming it).

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
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..analysis.executor import make_executor, stop_executor
from ..checkpoint import Journal, file_digest
from ..errors import (
    EstimationError,
    SimulationError,
)
from ..io import write_text_atomic
from ..simulation.models import close_models
from ..simulation.windows import (
    DEFAULT_WARMUP,
    Problem,
    WindowData,
    coarsen,
    load_windows,
    problem_from_spec,
    simulate_window,
    warmup_used,
)
from ..spec import write_starts as _write_starts
from .objective import Objective, fmt_values, jacobian_support
from .search import (
    default_maxiter,
    global_search,
    population_per_parameter,
    refine_estimate,
)
from .settings import (
    DEFAULT_GLOBAL_GRID,
    FAILED_COST,
    GLOBAL_SETTLE,
    JACOBIAN_METHODS,
    MAX_REFINE_ITERATIONS,
    ProgressCallback,
)

log = logging.getLogger(__name__)


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
        Warm-up asked for before each window (s).
    warmups
        Warm-up each window had (s): the measured history its run went through
        before it, shortened where the data have less (a window at the first
        sample: 0, the run starts from ``initial_state``).
    initial_state
        Where a run without history started: ``"model"`` (the FMU's own initial
        state) or ``"steady"`` (its steady state): the spec's ``[data] initial``.
    refinement
        How the local refinement ran: ``jacobian`` (``"exact"`` or ``"fd"``, what
        was used), ``requested`` (the ``jacobian`` setting), ``reason`` (why not
        exact, when it is not), ``runs`` (twin runs of the refinement; an exact
        run gives residuals and Jacobian together), ``seconds`` and ``cpu_seconds``
        (wall and process CPU time of the refinement; not in :meth:`to_json`, whose
        document a resumed run reproduces exactly). Empty without refinement.
    identifiability
        What the data could determine at the start values, checked before the search
        (:func:`trackingbox.identify.analysis.identify`'s ``to_json``; the estimate stage
        adds it); empty if not run.
    uncertainty
        Confidence intervals at the estimate (:class:`trackingbox.identify.intervals.Uncertainty`;
        the estimate stage adds them), or None.
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
    warmups: dict[str, float] = field(default_factory=dict)
    initial_state: str = "model"
    identifiability: dict[str, Any] = field(default_factory=dict)
    uncertainty: Any = None

    def shortened_warmups(self) -> dict[str, float]:
        """Window -> the warm-up it had, for the windows whose warm-up was shorter than asked for."""
        return {w: v for w, v in self.warmups.items() if v < self.warmup - 1e-9 * max(1.0, self.warmup)}

    def warmup_note(self) -> str:
        """One sentence on the warm-ups the windows had ("" when each had the one asked for)."""
        short = self.shortened_warmups()
        if not short:
            return ""
        start = ("the FMU's own initial state" if self.initial_state == "model"
                 else "the model's steady state")
        parts = ", ".join(f"the {w} window's to {v:g} s" for w, v in short.items())
        return (f"warm-up shortened to the measured history that exists ({self.warmup:g} s asked for): {parts}; "
                f"runs start there from {start} ([data] initial = \"{self.initial_state}\")")

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
        if self.shortened_warmups():  # only then: the document says what the data did not allow
            out["warmup"] = {"requested": float(self.warmup), "used": {k: float(v) for k, v in self.warmups.items()},
                             "initial": self.initial_state, "note": self.warmup_note()}
        if self.refinement:  # its timings stay out: a resumed run's document equals an uninterrupted one's
            out["refinement"] = {k: v for k, v in self.refinement.items() if k not in ("seconds", "cpu_seconds")}
        if self.identifiability:  # trackingbox.identify: the check before, the intervals after
            out["identifiability"] = self.identifiability
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty.to_json()
        return out


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
        Warm-up before each window (s), through the measured history (shortened to what exists); default
        :data:`DEFAULT_WARMUP`.
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
    try:
        return _estimate(spec, seed=seed, workers=workers, maxiter=maxiter, popsize=popsize, warmup=warmup,
                         refine=refine, refine_iterations=refine_iterations, progress=progress,
                         checkpoint=checkpoint, global_grid=global_grid, resume=resume,
                         refine_grid=refine_grid, jacobian=jacobian, scheduler=scheduler,
                         settle=float(settle))
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
        evaluations = (maxiter + 1) * population_per_parameter(n, popsize) * n
        if evaluations > MAX_GLOBAL_EVALUATIONS:
            problems.append(f"maxiter = {maxiter} and popsize = {popsize} ({population_per_parameter(n, popsize) * n} individuals) "
                            f"ask for up to {evaluations:.3g} simulations (at most {MAX_GLOBAL_EVALUATIONS:g})")
    if not problems and warmup is not None and spec.sample_time > 0:
        samples = (float(warmup) + span) / float(spec.sample_time)
        if samples > MAX_WINDOW_SAMPLES:
            problems.append(f"warmup = {warmup:g} s: a window and its warm-up would take {samples:.3g} samples "
                            f"of sample_time = {spec.sample_time:g} s (at most {MAX_WINDOW_SAMPLES:g})")
    if problems:
        raise EstimationError("estimate: " + "; ".join(problems))


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
    return make_executor(scheduler, workers if workers is not None or scheduler else 1, start_method="spawn")


def _close_pool(pool: Any, *, failed: bool = False) -> None:
    """Shut the executor down; after a failure or an interrupt without waiting for running evaluations."""
    if pool is not None:
        stop_executor(pool, wait=not failed)


def journal_path(checkpoint: str | Path) -> Path:
    """The evaluation journal kept beside an estimation checkpoint (``checkpoint.journal``)."""
    return Path(checkpoint).with_suffix(".journal")


def _identity(spec: Any, problem: Problem, **settings: Any) -> dict[str, Any]:
    """What makes two estimation runs the same search: the inputs' bytes and the settings."""
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
    warmups = {w.name: warmup_used(w) for w in (training, validation)}
    for name, used in warmups.items():
        if used < problem.warmup - 1e-9 * max(1.0, problem.warmup):
            log.warning("the %s window's warm-up is shortened from %g s to %g s (the measured history before "
                        "it); its runs start from %s", name, problem.warmup, used,
                        "the FMU's own initial state" if problem.initial == "model" else "the steady state")
    train = Objective(problem, training)
    valid = Objective(problem, validation, (training, validation))
    history: list[float] = []
    evaluations = 0
    refinement: dict[str, Any] = {}

    start_cost = journal.call("train", train, problem.start)
    evaluations += 1
    if start_cost >= FAILED_COST:
        log.warning("the twin fails at the start values; the global search starts without them")
    best_x, best_cost = problem.start.copy(), start_cost
    history.append(start_cost)
    log.info("start values: cost %.6g (%s)", start_cost, fmt_values(problem.names, best_x))

    pool = _open_pool(workers, scheduler) if maxiter > 0 or refine else None
    try:
        if maxiter > 0:
            stride = max(1, int(math.floor((global_grid or DEFAULT_GLOBAL_GRID) / problem.sample_time + 1e-9)))
            coarse = train
            if stride > 1:
                coarse = Objective(replace(problem, sample_time=problem.sample_time * stride),
                                   coarsen(training, stride))
            best_x, best_cost, n_global = global_search(
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
            refined_x, refined_cost, n_local = refine_estimate(
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
        warmups=warmups,
        initial_state=problem.initial,
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
            out[window.name] = _series(problem, window, parameter_sets, windows)
    finally:
        close_models()
    return out


def _series(problem: Problem, window: WindowData, parameter_sets: Mapping[str, Mapping[str, float]],
            history: tuple[WindowData, ...] = ()) -> pd.DataFrame:
    """Measured and simulated series of one window (lead-in left out)."""
    keep = slice(window.lead, None)
    frame: dict[str, np.ndarray] = {"time": window.time[keep]}
    for tag in problem.outputs:
        frame[tag] = window.measured[tag][keep]
    for label, values in parameter_sets.items():
        x = np.array([float(values.get(n, s)) for n, s in zip(problem.names, problem.start)])
        sim = simulate_window(problem, window, x, history=history)
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
    return _write_starts(path, values, intervals)
