"""Fit a candidate effect properly: patch the twin, compile it, estimate it with the spec's candidates.

:func:`fit_candidate` renders the effect into ``<Twin>Diagnosed``
(:func:`trackingbox.diagnose.library.render_patch`), compiles it on the embedded
path (:func:`~trackingbox.diagnose.library.compile_patch`, once per effect and
target: the FMU is cached in the work folder), writes the patched spec
(:func:`~trackingbox.diagnose.library.patched_spec`: same tags, sensor tags
re-mapped, the effect's parameters added to ``[[parameters]]``), sets the starts
to the null fit (the spec's candidates) and the screening values (the effect's
parameters, where the screening measured them), and runs
:func:`trackingbox.estimation.estimate` on it with a short budget. The fitted
twin's residuals on both windows are scored as the screening scores a transform
(:func:`trackingbox.diagnose.screen.score`).
"""
from __future__ import annotations

import hashlib
import logging
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import TrackingError
from ..estimation import estimate, jacobian_points
from ..fmu import read_info
from ..simulation.models import close_models
from ..simulation.windows import load_windows, problem_from_spec, simulate_window
from ..spec import load_spec, write_starts
from . import fmucache, library
from .candidates import (PIN_EVIDENCE, Candidate, at_bound, freed_evidence, joint, pinned_at_bounds, score,
                         training_score, zero_able)
from .residuals import fit_windows, step_bounds, window_series

if TYPE_CHECKING:
    from .residuals import WhereResult

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FitBudget:
    """Budget of a candidate's estimation.

    Attributes
    ----------
    maxiter
        Generations of the global search (0: refinement from the warm start only).
    refine_iterations
        Least-squares iterations of the refinement.
    workers
        Processes for the estimation.
    warmup
        Warm-up before each window (s); None: the estimation's default.
    grid
        Grid step (s) of the refinement's cost (``refine_grid`` of
        :func:`trackingbox.estimation.estimate`); None: the full grid. The candidate is
        scored on the full grid.
    scheduler
        Dask scheduler of the estimation's evaluations (``scheduler`` of
        :func:`trackingbox.estimation.estimate`); None: local processes.
    jacobian
        The refinement's Jacobian (``jacobian`` of :func:`trackingbox.estimation.estimate`).
    """

    maxiter: int = 0
    refine_iterations: int = 8
    workers: int | None = None
    warmup: float | None = None
    grid: float | None = None
    scheduler: str | None = None
    jacobian: str = "prefer-exact"


@dataclass(frozen=True)
class FitOutcome:
    """What fitting one candidate produced (kept on :attr:`Candidate.fit`)."""

    patch: Any
    fmu: Path
    spec_path: Path
    estimate: Any
    effect_parameters: dict[str, str]   # short effect parameter name -> full name in the patched twin


def _get(obj: Any, name: str, default: Any = None) -> Any:
    if isinstance(obj, Mapping):
        return obj.get(name, default)
    return getattr(obj, name, default)


def render(spec: Any, effect: Any, target: str, values: Mapping[str, float]) -> Any:
    """``library.render_patch`` of one effect on one target with *values*."""
    return library.render_patch(spec, [library.Finding(effect.id, target, dict(values))],
                                effects={effect.id: effect})


def _short(full: str, effect: Any) -> str:
    """The effect's own parameter name in a patch parameter's full name (``sensorBias_TI_102_b`` -> ``b``)."""
    for p in getattr(effect, "parameters", ()) or ():
        if full == p.name or full.endswith(("_" + p.name, "." + p.name)):
            return p.name
    return full


def warm_values(effect: Any, screened: Candidate | None,
                bounds: Mapping[str, tuple[float, float]] | None = None,
                starts: Mapping[str, float] | None = None) -> dict[str, float]:
    """Start values of the effect's parameters: its starts, or the screening's estimate where it is the same quantity.

    A one-parameter ``bias`` entry starts at the screened bias, a one-parameter
    ``lag`` entry at the screened time constant, a one-parameter ``drift`` or
    ``coefficient-ramp`` entry at the screened rate (per second), a multi-parameter entry
    at the screened values of its parameters' names; the value is clipped to the
    parameter's bounds (*bounds*: short name -> (min, max) as the patch resolved them for
    the target's unit; else the entry's own); *starts*: the starts as the patch resolved them (per unit of
    the target's size, ``per``), else the entry's own.

    >>> from types import SimpleNamespace as NS
    >>> e = NS(screen="bias", parameters=[NS(name="b", start=0.0, min=-2.0, max=2.0)])
    >>> warm_values(e, NS(values={"bias": 0.7}))
    {'b': 0.7}
    >>> warm_values(e, NS(values={"b": 9.0}))
    {'b': 2.0}
    """
    params = list(getattr(effect, "parameters", ()) or ())
    values = {p.name: float((starts or {}).get(p.name, p.start)) for p in params}
    key = {"bias": "bias", "lag": "tau", "drift": "rate", "coefficient-ramp": "rate"}.get(
        getattr(effect, "screen", ""))
    if screened is not None and key and len(params) == 1 and (key in screened.values
                                                             or params[0].name in screened.values):
        p = params[0]
        v = float(screened.values.get(p.name, screened.values.get(key, math.nan)))
        lo, hi = (bounds or {}).get(p.name, (float(p.min), float(p.max)))
        if math.isfinite(v):
            values[p.name] = float(min(max(v, lo), hi))
    elif screened is not None and len(params) > 1:
        # a multi-parameter screening reports the entry's own names (levelling-drift, levelling-ramp)
        for p in params:
            v = float(screened.values.get(p.name, math.nan))
            lo, hi = (bounds or {}).get(p.name, (float(p.min), float(p.max)))
            if math.isfinite(v):
                values[p.name] = float(min(max(v, lo), hi))
    return values


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def level(where: WhereResult, after_t: dict[str, np.ndarray],
          after_v: dict[str, np.ndarray], x: np.ndarray | None = None,
          ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Move a fitted candidate's residuals to the noise-weighted optimum of the spec's candidates.

    The estimation minimises the mean NRMSE, the null model was moved to the
    noise-weighted least-squares optimum (:func:`trackingbox.diagnose.residuals.polish`);
    one linearised step with the null model's output Jacobian puts the fitted
    candidate on the same footing, so that a mere shift along the trade-off between
    tags is not credited to the effect. The varying candidates move as in the null
    (:mod:`trackingbox.diagnose.varying`).
    """
    j_train, j_val = where.jacobian
    if not j_train or not all(t in j_train for t in after_t):
        return after_t, after_v
    # the step keeps the spec's candidates (fitted at *x*) inside their bounds, as the null's polish does
    bounds = step_bounds(where.problem, x) if x is not None else None
    fit = fit_windows(after_t, after_v, (j_train, j_val), where.noise, bounds=bounds,
                      varying=getattr(where, "varying", None), x=x)
    return fit.after_train, fit.after_valid


def fit_candidate(spec: Any, where: WhereResult, effect: Any, target: str, work_dir: Path, *,
                  screened: Candidate | None = None, budget: FitBudget = FitBudget(),
                  stage: str = "fit") -> Candidate:
    """Patch, compile and estimate one effect on one target; score it against the null model.

    Parameters
    ----------
    spec
        The loaded spec.
    where
        The null model's residuals.
    effect, target
        The library entry and its target.
    work_dir
        Folder for the patch, its FMU and its spec (one sub-folder per effect and target).
    screened
        The candidate's screening (warm start of the effect's parameters).
    budget
        The estimation's budget.
    stage
        Label of the result (``"fit"``; ``"screen"`` when used as the screening of a compile-only entry).

    Returns
    -------
    Candidate
        With :attr:`Candidate.fit` = :class:`FitOutcome`.
    """
    prepared = prepare(spec, where, effect, target, work_dir, screened=screened)
    patch, fmu, spec_path, full, bounds = (prepared.patch, prepared.fmu, prepared.spec_path, prepared.full,
                                           prepared.bounds)
    pspec = prepared.spec
    log.info("fitting %s on %s (%d parameters)", effect.id, target, len(pspec.parameters))
    est = estimate(pspec, maxiter=budget.maxiter, refine=True, refine_iterations=budget.refine_iterations,
                   workers=budget.workers, warmup=budget.warmup, refine_grid=budget.grid,
                   scheduler=budget.scheduler, jacobian=budget.jacobian)
    problem = problem_from_spec(pspec, warmup=budget.warmup)
    training, validation = load_windows(pspec, warmup=problem.warmup)
    x = np.array([est.parameters.get(n, s) for n, s in zip(problem.names, problem.start)])
    fitted = {s: float(est.parameters[f]) for s, f in full.items() if f in est.parameters}
    # each effect parameter at a bound: the patched twin once more per window, moved inside by LINEAR_STEP
    sides = {s: side for s, v in fitted.items()
             if s in bounds and zero_able(*bounds[s]) and (side := at_bound(v, *bounds[s]))}
    try:
        # a carried state (a scale) starts the validation run where the training run had it
        both = (training, validation)
        series = [window_series(problem, w, x, pspec.inputs, both) for w in both]
        where = patched_varying(where, problem, (training, validation), x, pspec.inputs, series)
        inside = {}
        for short, side in sides.items():
            i = list(problem.names).index(full[short])
            h = LINEAR_STEP * (bounds[short][1] - bounds[short][0])
            xi = x.copy()
            xi[i] -= side * h
            inside[short] = (h, [window_series(problem, w, xi, pspec.inputs, both) for w in both])
    finally:
        close_models()
    tags = [t for t in pspec.outputs if t in where.tags]
    after_t = {t: series[0].residual(t) for t in tags}
    after_v = {t: series[1].residual(t) for t in tags}
    fitted_x = np.array([float(est.parameters.get(n, xn)) for n, xn in zip(where.problem.names, where.x)]) \
        if where.x is not None else None
    after_t, after_v = level(where, after_t, after_v, fitted_x)
    # at a bound and held there by the data beyond noise (PIN_EVIDENCE): the move beyond the bound, linearised
    evidence = {}
    for short, (h, moved) in inside.items():
        # d(output)/d(parameter): the inside point is side * h below it
        column = tuple({t: (s.simulated[t] - m.simulated[t]) / (sides[short] * h) for t in tags}
                       for s, m in zip(series, moved))
        evidence[short] = freed_evidence(where, (after_t, after_v), column, sides[short], x=fitted_x)
    pinned = pinned_at_bounds(fitted, bounds, evidence)
    k = len(getattr(effect, "parameters", ()) or ()) or 1
    outcome = FitOutcome(patch, fmu, spec_path, est, full)
    return score(effect.id, target, getattr(effect, "kind", "process"), stage, where, k, after_t, after_v, fitted,
                 pinned=pinned, fit=outcome, reason=_bound_note(evidence, pinned))


def _bound_note(evidence: Mapping[str, float], pinned: Sequence[str]) -> str:
    """The candidate's remark on its parameters at a bound: the evidence that holds each there."""
    if not evidence:
        return ""
    return "at a bound: " + ", ".join(
        f"{k} ({'pinned' if k in pinned else 'within noise'}, evidence {v:.3g}; pinned above {PIN_EVIDENCE:g})"
        for k, v in evidence.items())


def patched_varying(where: WhereResult, problem: Any, windows: Sequence[Any], x: np.ndarray,
                    inputs: Mapping[str, str], series: Sequence[Any]) -> WhereResult:
    """*where* with its Jacobian's columns of the ``[diagnose] varying`` candidates taken from the patched twin at *x*.

    The levelling lets a fouling move in time through its output sensitivity; an effect that changes
    that sensitivity must be levelled with its own. A dry-solids meter reading ``(1 + g) x`` moves by
    ``1 + g`` times the null twin's ``dx/dRf``: on the evaporator (24 h, seed 0; the null twin's QI-6150
    sensitivity -45.7 per m2.K/W, training mean) with the ``density-meter`` case's g = 0.069 and the
    fouling rising 5.6e-5 m2.K/W over the 12 h training window, the null's column leaves
    ``g dx/dRf dRf`` = -1.8e-4 of dry solids as a falling trend in QI-6150 (-4e-9 1/s, 0.4 of the
    ``ds-meter`` drift's bound) for that drift to take up. One run per window and varying candidate
    (forward difference, as the null's Jacobian: :func:`trackingbox.diagnose.residuals.series_and_jacobian`);
    *series*: the patched twin's runs at *x* on *windows*.
    """
    basis = getattr(where, "varying", None)
    if basis is None or where.problem is None or not where.jacobian[0]:
        return where
    names = list(problem.names)
    jac = [{t: np.array(j, dtype=float, copy=True) for t, j in w.items()} for w in where.jacobian]
    for i in basis.index:
        name = where.problem.names[i]
        if name not in names:
            continue
        k = names.index(name)
        points, h = jacobian_points(x, problem.lower, problem.upper, 1.0e-3)
        for w, base, cols in zip(windows, series, jac):
            moved = window_series(problem, w, points[k], inputs, tuple(windows))
            for t, c in cols.items():
                if t in moved.simulated and c.shape[1] > i:
                    c[:, i] = (moved.simulated[t] - base.simulated[t]) / h[k]
    return replace(where, jacobian=(jac[0], jac[1]))


def fit_job(spec: Any, where: WhereResult, effect: Any, screened: Candidate, work_dir: Path,
            budget: FitBudget) -> Candidate:
    """:func:`fit_candidate` of a screened candidate (module level, so a worker process can run it).

    A fit that fails on purpose (a :class:`trackingbox.errors.TrackingError`: the twin
    failed, the patch did not compile) leaves the screening, marked ``skipped`` with the reason.
    """
    try:
        return fit_candidate(spec, where, effect, screened.target, work_dir, screened=screened, budget=budget)
    except TrackingError as exc:
        log.warning("fitting %s on %s failed: %s", screened.effect, screened.target, exc)
        return Candidate(screened.effect, screened.target, screened.kind, "skipped",
                         delta_bic=screened.delta_bic, reason=f"fit failed: {exc}")


# --------------------------------------------------------------------------- patch preparation, linearised screen


@dataclass(frozen=True)
class Prepared:
    """A candidate's patched twin, compiled, with its spec (starts: the null fit and the effect's warm start).

    Attributes
    ----------
    patch
        The rendered patch (:class:`trackingbox.diagnose.library.Patch`).
    fmu, spec_path, spec
        Its FMU, the patched spec's path and the loaded patched spec.
    full
        Short effect parameter name -> full name in the patched twin.
    bounds
        Short effect parameter name -> (min, max) as the patch resolved them.
    start
        Short effect parameter name -> start value.
    """

    patch: Any
    fmu: Path
    spec_path: Path
    spec: Any
    full: dict[str, str]
    bounds: dict[str, tuple[float, float]]
    start: dict[str, float]


def prepare(spec: Any, where: WhereResult, effect: Any, target: str, work_dir: Path, *,
            screened: Candidate | None = None) -> Prepared:
    """Render, compile (once per effect and target: cached in the work folder) and write the patched spec.

    The effect's parameters are tunable, so one FMU per effect and target serves every
    value; the patched spec starts at the null fit (the spec's candidates) and at the
    effect's warm start (:func:`warm_values`).
    """
    folder = Path(work_dir) / _safe(f"{effect.id}-{target}")
    folder.mkdir(parents=True, exist_ok=True)
    first = render(spec, effect, target, {})
    bounds = {_short(p.name, effect): (float(p.min), float(p.max)) for p in first.parameters}
    start = warm_values(effect, screened, bounds, {_short(p.name, effect): float(p.start) for p in first.parameters})
    if screened is not None and getattr(effect, "screen", "") == "compile":
        # a linearised screening (screen_compiled) measured the entry's own parameters
        for short, v in screened.values.items():
            if short in bounds and math.isfinite(v):
                start[short] = float(min(max(v, bounds[short][0]), bounds[short][1]))
    patch = render(spec, effect, target, start)
    fmu = folder / f"{patch.model.rsplit('.', 1)[-1]}.fmu"
    marker = folder / ".compiled"
    key = _compile_key(spec, first)
    if not (fmu.is_file() and marker.is_file() and marker.read_text() == key):
        # the same patch compiled by an earlier diagnosis (another case of the bench, a rerun): its FMU
        shared = fmucache.key(key, _source_libraries(spec))
        if not fmucache.fetch(shared, fmu):
            fmu = Path(library.compile_patch(patch, folder, libraries=_source_libraries(spec)).fmu)
            fmucache.store(shared, fmu)
        marker.write_text(key)
    spec_path = Path(library.patched_spec(spec, patch, folder, fmu))
    full = {_short(p.name, effect): p.name for p in patch.parameters}
    starts = {n: float(v) for n, v in where.null.parameters.items()}
    starts.update({full[s]: v for s, v in start.items() if s in full})
    if screened is not None and getattr(effect, "screen", "") == "compile":
        # the linearised screening's candidates (screen_compiled), where it moved them
        starts.update({n: float(v) for n, v in screened.values.items() if n in where.null.parameters})
    pspec = load_spec(spec_path)
    known = set(pspec.parameter_names)
    write_starts(spec_path, {k: v for k, v in starts.items() if k in known})
    return Prepared(patch, fmu, spec_path, load_spec(spec_path), full, bounds, start)


def _source_libraries(spec: Any) -> tuple[Path, ...]:
    """The libraries the twin's source uses (``[source] libraries``), none without a ``[source]``."""
    source = getattr(spec, "source", None)
    return tuple(source.libraries) if source is not None else ()


def _compile_key(spec: Any, structure: Any) -> str:
    """What decides a patched twin's FMU: the patch rendered at the entry's own starts, and the twin's source.

    The effect's parameters are tunable, so the start values the patch is rendered with
    do not change the FMU; an edited entry, template or twin source does (a work folder
    reused after such an edit must not hand back the old FMU).
    """
    h = hashlib.sha256(structure.model.encode() + b"\0" + structure.source.encode())
    source = getattr(getattr(spec, "source", None), "path", None)
    if source is not None:
        root = Path(source)
        files = sorted(root.rglob("*.mo")) if root.is_dir() else [root]
        for f in files:
            h.update(str(f.relative_to(root) if root.is_dir() else f.name).encode() + b"\0")
            h.update(f.read_bytes())
    return h.hexdigest()


#: Forward-difference step of the linearised screen, as a share of each effect parameter's bound range.
LINEAR_STEP = 1.0e-2


def quartile_starts(values: Any, lo: float, hi: float, start: float) -> list[float]:
    """Linearisation points of an onset parameter besides its *start*: the quartiles of the variable it is a
    threshold of (*values*, finite ones), inside ``[lo, hi]``, each at least 1 % of the range from the start
    and from each other.

    >>> quartile_starts([0.70, 0.78, 0.80, 0.82, 0.90], 0.4, 0.85, 0.5)
    [0.78, 0.8, 0.82]
    >>> quartile_starts([0.3, 0.3, 0.3], 0.4, 0.85, 0.5)
    [0.4]
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    out: list[float] = []
    if not v.size:
        return out
    for q in np.quantile(v, (0.25, 0.5, 0.75)):
        q = float(min(max(q, lo), hi))
        if all(abs(q - o) > 0.01 * (hi - lo) for o in (start, *out)):
            out.append(q)
    return out


def onset_starts(effect: Any, target: str, problem: Any, window: Any, x: np.ndarray,
                 full: Mapping[str, str], variables: Sequence[str] | None = None) -> list[np.ndarray]:
    """Further points *x* for the linearised screen of an entry with an onset (``onset_of``): each onset
    parameter at the quartiles of its variable on *target* over the patched twin's run at *x* on *window*.

    A threshold law (scale above a dry-solids onset) linearised at an onset the variable never crosses is a
    constant growth: the same column as the tracked fouling's rise, which the null model's varying fouling
    already carries, and a zero column in the onset itself. Its form is only seen, and its onset only
    identified, where the variable crosses the onset; the quartiles of the twin's own variable are where it
    does. One run of the patched twin with that variable as an extra output (*variables*: the twin's
    variable names; None: read from its FMU).
    """
    names = list(problem.names)
    onsets = {p.name: p.onset_of for p in getattr(effect, "parameters", ()) or ()
              if getattr(p, "onset_of", "") and full.get(p.name) in names}
    if not onsets:
        return []
    known = {v.name for v in read_info(problem.twin).variables} if variables is None else set(variables)
    # an array target (the train's effect[k]) pools its elements' variable
    extra = {f"__onset_{short}_{j}": v for short, var in onsets.items()
             for j, v in enumerate(n for n in sorted(known) if re.fullmatch(
                 re.escape(target) + r"(\[\d+\])?\." + re.escape(var), n))}
    if not extra:
        return []
    run = simulate_window(replace(problem, outputs={**problem.outputs, **extra}), window, x)
    points = []
    for short in onsets:
        i = names.index(full[short])
        pooled = [run[k][window.lead:] for k in extra if k.startswith(f"__onset_{short}_")]
        for q in quartile_starts(np.concatenate(pooled) if pooled else [], float(problem.lower[i]),
                                 float(problem.upper[i]), float(x[i])):
            xq = np.array(x, dtype=float, copy=True)
            xq[i] = q
            points.append(xq)
    return points


def screen_compiled(spec: Any, where: WhereResult, effect: Any, target: str, work_dir: Path, *,
                    step: float = LINEAR_STEP, rank_on_training: bool = True) -> Candidate:
    """Screen a ``compile`` entry cheaply: its patched twin linearised in the effect's parameters.

    The patch is compiled (:func:`prepare`) and simulated on both windows at the
    null fit with the effect at its start ``e0``, and once more per effect
    parameter moved by *step* of its bound range: ``1 + k`` runs per window
    instead of an estimation. The effect's output sensitivity ``D`` enters the
    joint least squares with the null model's sensitivity to the spec's
    candidates (:func:`trackingbox.diagnose.screen.joint`), exactly as a sensor
    transform's columns do. A value outside its bounds is clipped there and the
    candidates refitted with the effect fixed. The candidate is scored like any
    screening (``stage = "screen"``, ``fit = None``); the best ones are then fitted
    properly (:func:`fit_candidate`). An entry with an onset parameter (``onset_of``)
    is linearised at its start and at each point of :func:`onset_starts`; the best
    ΔBIC is kept: the points are ranked on the training window's runs alone (the ΔBIC is
    training's), and the validation window is run at the best point only (*rank_on_training*
    False: every point on both windows, the same candidate; on the 3-effect train's
    ``soluble-scale``, four points of three parameters, 12 of 32 runs fewer per target).

    Parameters
    ----------
    spec, where, effect, target, work_dir
        As :func:`fit_candidate`.
    step
        Forward-difference step (share of each effect parameter's range).

    Returns
    -------
    Candidate
    """
    prepared = prepare(spec, where, effect, target, work_dir)
    pspec = prepared.spec
    problem = problem_from_spec(pspec, warmup=where.problem.warmup if where.problem is not None else None)
    windows = load_windows(pspec, warmup=problem.warmup)
    names = list(problem.names)
    x0 = np.array([where.null.parameters.get(n, s) for n, s in zip(names, problem.start)], dtype=float)
    try:
        points = [x0, *onset_starts(effect, target, problem, windows[0], x0, prepared.full)]
        runs: list[dict[int, Any]] = [{} for _ in points]
        if len(points) > 1 and rank_on_training:
            # the ΔBIC is the training window's alone: the points are ranked on their training runs, and
            # only the best one's validation runs are made (the same candidate as all points run on both)
            ranked = [_linearised(where, effect, target, prepared, problem, windows, x, step, runs=r,
                                  validation=False) for x, r in zip(points, runs)]
            best = max(range(len(points)), key=lambda i: _finite(ranked[i].delta_bic))
            points, runs = [points[best]], [runs[best]]
        found = [_linearised(where, effect, target, prepared, problem, windows, x, step, runs=r)
                 for x, r in zip(points, runs)]
    finally:
        close_models()
    return max(found, key=lambda c: _finite(c.delta_bic))


def _finite(x: float) -> float:
    """*x*, or minus infinity where it is not finite (a ranking's key)."""
    return x if math.isfinite(x) else -math.inf


def _linearised(where: WhereResult, effect: Any, target: str, prepared: Prepared, problem: Any,
                windows: Sequence[Any], x0: np.ndarray, step: float, *, runs: dict[int, Any] | None = None,
                validation: bool = True) -> Candidate:
    """:func:`screen_compiled` at one point *x0* of the patched twin's parameters (runs; no close).

    *runs*: window index -> the residual at *x0* and the effect's columns on that window, filled
    here where missing (a second call at the same point makes no run again). Without *validation*
    only the training window is run, and the candidate carries its ΔBIC alone (which is the
    training window's: :func:`trackingbox.diagnose.candidates.training_score`).
    """
    pspec = prepared.spec
    names = list(problem.names)
    shorts = [s for s in prepared.full if prepared.full[s] in names]
    idx = [names.index(prepared.full[s]) for s in shorts]
    # the polishing step of the null model (residuals.polish) applies to the patched twin as well
    cand_names = list(where.problem.names) if where.problem is not None else []
    raw = np.array([where.null.parameters.get(n, s) for n, s in zip(cand_names, where.problem.start)]) \
        if where.problem is not None else np.zeros(0)
    delta0 = (np.asarray(where.x, dtype=float) - raw) if where.x is not None and raw.size else np.zeros(0)
    tags = [t for t in pspec.outputs if t in where.tags]
    base, cols = [], []
    runs = {} if runs is None else runs
    points, h = jacobian_points(x0[idx], problem.lower[idx], problem.upper[idx], step)
    for i_w, (w, jac) in enumerate(zip(windows, where.jacobian)):
        if i_w and not validation:
            break
        if i_w not in runs:
            b = window_series(problem, w, x0, pspec.inputs, tuple(windows))
            shift = {t: (jac[t] @ delta0 if t in jac and delta0.size else 0.0) for t in tags}
            per_tag: dict[str, list[np.ndarray]] = {t: [] for t in tags}
            for point, hj in zip(points, h):
                x = x0.copy()
                x[idx] = point
                s = window_series(problem, w, x, pspec.inputs, tuple(windows))
                for t in tags:
                    per_tag[t].append((s.simulated[t] - b.simulated[t]) / hj)
            runs[i_w] = ({t: b.measured[t] - b.simulated[t] - shift[t] for t in tags},
                         {t: np.column_stack(c) for t, c in per_tag.items()})
        base.append(runs[i_w][0])
        cols.append(runs[i_w][1])
    r_val, c_val = (base[1], cols[1]) if validation else (None, None)
    beta, after_t, after_v, _, step_c = joint(where, base[0], r_val, cols[0], c_val)
    e0 = x0[idx]
    lo, hi = problem.lower[idx], problem.upper[idx]
    value = e0 + beta
    clipped = np.clip(value, lo, hi)
    evidence: dict[str, float] = {}
    if np.any(clipped != value):
        # outside the bounds: fix the effect at the clipped value, refit the candidates alone
        moved = clipped - e0
        fixed = [{t: r[t] - cols[k][t] @ moved for t in tags} for k, r in enumerate(base)]
        _, after_t, after_v, _, step_c = joint(where, fixed[0], fixed[1] if validation else None)
        # a clipped parameter is pinned only if the data hold it there beyond noise (PIN_EVIDENCE)
        for i, short in enumerate(shorts if validation else ()):
            side = at_bound(float(clipped[i]), float(lo[i]), float(hi[i]))
            if side and clipped[i] != value[i] and zero_able(float(lo[i]), float(hi[i])):
                evidence[short] = freed_evidence(where, (fixed[0], fixed[1]),
                                                 tuple({t: c[t][:, i] for t in tags} for c in cols), side)
    pinned = pinned_at_bounds(dict(zip(shorts, map(float, clipped))),
                              {s: (float(a), float(b)) for s, a, b in zip(shorts, lo, hi)}, evidence)
    k = len(getattr(effect, "parameters", ()) or ()) or 1
    if not validation:
        return Candidate(effect.id, target, getattr(effect, "kind", "process"), "screen",
                         delta_bic=training_score(where, k, after_t)[0])
    values = {s: float(v) for s, v in zip(shorts, clipped)}
    # where the joint fit moved the spec's candidates (from the polished null), inside their bounds: the
    # warm start of the proper fit (prepare), so that it does not start with the effect counted twice
    if where.problem is not None and step_c.size == len(cand_names) and where.x is not None:
        moved = np.clip(np.asarray(where.x, dtype=float) + step_c, where.problem.lower, where.problem.upper)
        values.update({n: float(v) for n, v in zip(cand_names, moved)})
    return score(effect.id, target, getattr(effect, "kind", "process"), "screen", where, k, after_t, after_v,
                 values, pinned=pinned, reason=_bound_note(evidence, pinned))
