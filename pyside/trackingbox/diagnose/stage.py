"""The diagnosis stage: ``diagnose(spec, settings) -> DiagnosisResult``.

1. **Where** (:mod:`.residuals`): fit the null model (the spec's candidates on
   the training window; by default the least-squares refinement from the spec's
   starts, see :attr:`DiagnoseSettings.maxiter`) and describe every tag's
   residual against its noise.
2. **Which** (:mod:`.screen`): screen every effect of the library on every
   target it applies to; rank by the BIC gain on training. With
   ``settings.compile`` the ``compile``-only entries are compiled once each and
   linearised in their parameters (:func:`.fit.screen_compiled`).
3. **Fit** (:mod:`.fit`, with ``settings.compile``): the best
   ``settings.fit_best`` screened candidates are fitted properly through their
   patched, compiled twin, jointly with the spec's candidates, warm-started from
   the null fit and the screening.
   Without ``compile`` the screening results are judged (a sensor transform is
   the effect itself; the fouling ramp is its time-varying form) and nothing is
   compiled.
4. **Judge** (:mod:`.judge`) on the validation window; name at most one effect.
5. **Patch**: the named effect rendered as ``<Twin>Diagnosed.mo`` (and, with
   ``compile``, its FMU); with ``out_dir`` the Modelica file and the patched
   spec are written there.

``diagnose`` reads the spec, the twin and the measurements only. The wall and
CPU time of each phase (``null``, ``screen`` (with the compiled screens), ``fit``,
``judge``, ``patch``) are in :attr:`DiagnosisResult.timings`.
"""
from __future__ import annotations

import logging
import math
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..analysis.executor import make_executor
from ..data.view import kept_tables
from ..errors import SpecError, did_you_mean
from . import library
from .candidates import Candidate
from .fit import FitBudget, _short, fit_job, render, warm_values
from .judge import Judgement, judge, objections, reasons_against, validation_samples
from .parallel import pool, submit
from .residuals import WhereResult, where
from .screen import rank, screen

log = logging.getLogger(__name__)

#: ``progress(stage, done, total)``: stages ``"null"``, ``"screen"``, ``"fit"``.
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class DiagnoseSettings:
    """Settings of :func:`diagnose` (the command's options, same names).

    Attributes
    ----------
    effects
        Effect ids to consider (all when empty).
    compile
        Fit the best candidates through their patched, compiled twins and build
        the named patch's FMU; without it only the cheap screening runs.
    fit_best
        How many screened candidates are fitted properly in a round (with ``compile``): those whose
        screening passes the judge's tests first (:func:`trackingbox.diagnose.judge.objections`),
        each group by ΔBIC; the first round adds the candidate with the largest ΔBIC where it is not
        among them (:func:`next_fits`).
    fit_rounds
        Rounds of fits at most: after the first, another round fits the next candidates whose
        screening passes, as long as no fitted candidate passes.
    out_dir
        Where ``<Twin>Diagnosed.mo`` and the patched spec are written (None: not written).
    work_dir
        Folder for patches and FMUs of the fits (None: a temporary folder; ``out_dir/work`` when given).
    seed, warmup
        The null estimation's options (:func:`trackingbox.estimation.estimate`).
    workers
        Processes for the estimations (null and candidates) and for the null model's
        series and output Jacobian; None: two (at most the machine's cores) when the
        spec has more than three candidates, whose Jacobians then spread over them, else
        one (a worker's start-up is not worth it). The screening's expensive jobs (ramps,
        compiled patches; :mod:`trackingbox.diagnose.parallel`) use *workers* when given,
        else two (at most the machine's cores).
    maxiter
        Generations of the null estimation's global search; None (default): 0, the
        least-squares refinement from the spec's starts only, whose cost grows with the
        number of parameters (``1 + n`` runs per iteration) instead of a fixed
        population budget. The null model is polished afterwards
        (:func:`trackingbox.diagnose.residuals.polish`), and a spec's starts are
        normally an estimate already; give a number where they are far off.
    fit_iterations
        Refinement iterations of each candidate's estimation; None: sized to its number of
        parameters ``n`` (:func:`iterations_for`, :data:`FIT_RUNS` runs a pass, at most 8).
    fit_min_delta_bic
        Only candidates whose screening beats the null by more than this ΔBIC are fitted
        (half the naming threshold :data:`trackingbox.diagnose.judge.MIN_DELTA_BIC`, so a
        fit may still gain; a candidate the screening puts at the null's level costs a fit
        and cannot be named).
    null_iterations
        Refinement iterations of the null estimation; None: sized to the spec's number of
        candidates (:func:`iterations_for`, :data:`NULL_RUNS` runs a pass).
    grid
        Grid step (s) of the cost the estimations (null and candidates) refine on
        (``refine_grid`` of :func:`trackingbox.estimation.estimate`; a run's cost grows
        with its grid points). The null model's residuals, the screening and the scores
        are on the full grid; the null is polished there
        (:func:`trackingbox.diagnose.residuals.polish`) and each fitted candidate levelled
        (:func:`trackingbox.diagnose.fit.level`). None: 60 s when the spec has more than
        three candidates (each refinement iteration then costs many runs), else the full
        grid; 0: the full grid.
    relinearise
        How many of the best sensor candidates are screened again around where their joint
        fit moved the spec's candidates (:func:`trackingbox.diagnose.screen.screen`; each
        costs ``2 (1 + n)`` full-grid runs for ``n`` candidates); None: three, but only one
        when ``n`` is larger than 3.
    scheduler
        Run the parallel work (the pools' jobs, and the estimations' evaluations where
        they use more than one worker) on a Dask cluster instead of spawned processes:
        a scheduler's address (``tcp://host:8786``), or ``"local"`` for one local
        cluster of *workers* (default 2) processes for the whole diagnosis
        (:func:`trackingbox.analysis.executor.make_executor`). The phases' CPU times
        then leave out the cluster's workers.
    jacobian
        The estimations' refinement Jacobian (``jacobian`` of
        :func:`trackingbox.estimation.estimate`). Default ``"prefer-exact"``: the
        exact sensitivities where the twin supports them, even where finite
        differences on the native stepper cost less (``estimate``'s ``"auto"``).
        Diagnosis must not take a parameter error for a missing effect, so its null
        model is fitted as accurately as the twin allows (on heat production fd
        reached a 1 % higher training cost in the same iterations,
        ``scripts/bench_jacobian``), and the hidden-effect suite was measured so.
    exclude
        ``"effect@target"`` candidates not screened (:func:`trackingbox.diagnose.apply.apply`: the
        effects already applied to the twin).
    varying_step
        Knot spacing (s) of the spec's ``[diagnose] varying`` candidates, which the null model
        lets move in time as tracking would (:mod:`trackingbox.diagnose.varying`); None: the
        spec's ``[pairing] closed_loop``, else 3 h.
    """

    effects: tuple[str, ...] = ()
    compile: bool = False
    fit_best: int = 2
    fit_rounds: int = 3
    out_dir: Path | None = None
    work_dir: Path | None = None
    seed: int = 0
    workers: int | None = None
    maxiter: int | None = None
    warmup: float | None = None
    fit_iterations: int | None = None
    fit_min_delta_bic: float = 5.0
    null_iterations: int | None = None
    grid: float | None = None
    relinearise: int | None = None
    scheduler: str | None = None
    jacobian: str = "prefer-exact"
    varying_step: float | None = None
    exclude: tuple[str, ...] = ()


#: Runs (simulations) a refinement pass of the null estimation may cost about (:func:`iterations_for`).
NULL_RUNS = 120
#: Runs a refinement pass of a candidate's estimation may cost about (:func:`iterations_for`).
FIT_RUNS = 64


def iterations_for(n_parameters: int, runs: int, *, least: int = 3, most: int = 20) -> int:
    """Least-squares iterations that cost about *runs* simulations for *n_parameters* (``1 + n`` each).

    >>> iterations_for(1, 64), iterations_for(15, 64), iterations_for(14, 120), iterations_for(40, 64)
    (20, 4, 8, 3)
    """
    return max(least, min(most, runs // (1 + max(n_parameters, 0))))


@dataclass(frozen=True)
class PhaseTime:
    """Wall and CPU time of one phase of :func:`diagnose` (CPU: this process and its finished children)."""

    wall: float
    cpu: float

    def to_json(self) -> dict[str, float]:
        """``{"wall": s, "cpu": s}``."""
        return {"wall": round(self.wall, 3), "cpu": round(self.cpu, 3)}


class _Clock:
    """Accumulates :class:`PhaseTime` per phase name."""

    def __init__(self) -> None:
        self.phases: dict[str, PhaseTime] = {}
        self._phase: str | None = None
        self._t = (0.0, 0.0)

    @staticmethod
    def _now() -> tuple[float, float]:
        t = os.times()
        return time.perf_counter(), t.user + t.system + t.children_user + t.children_system

    def start(self, phase: str) -> None:
        self.stop()
        self._phase, self._t = phase, self._now()

    def stop(self) -> None:
        if self._phase is None:
            return
        wall, cpu = self._now()
        old = self.phases.get(self._phase, PhaseTime(0.0, 0.0))
        self.phases[self._phase] = PhaseTime(old.wall + wall - self._t[0], old.cpu + cpu - self._t[1])
        self._phase = None


@dataclass(frozen=True)
class DiagnosisResult:
    """What :func:`diagnose` found (``to_json()`` is the ``diagnose --json`` document)."""

    verdict: str
    named: Candidate | None
    candidates: tuple[Candidate, ...]
    where: WhereResult
    judgement: Judgement
    patch: Any = None
    patch_fmu: Path | None = None
    patch_spec: Path | None = None
    patch_file: Path | None = None
    seconds: float = 0.0
    effects: dict[str, str] = field(default_factory=dict)
    timings: dict[str, PhaseTime] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The issue's contract: verdict, findings, candidates, where, patch, seconds."""
        findings = []
        if self.named is not None:
            c = self.named
            findings.append({
                "effect": c.effect, "target": c.target,
                "parameters": {k: _num(v) for k, v in c.values.items()},
                "delta_bic": _num(c.delta_bic), "tags": list(c.tags),
                "validation": {"nrmse_before": {k: _num(v) for k, v in c.nrmse_before.items()},
                               "nrmse_after": {k: _num(v) for k, v in c.nrmse_after.items()}},
                "whiteness": {k: _num(v) for k, v in c.whiteness.items()},
                "explanation": self.effects.get(c.effect, ""),
                "stage": c.stage,
            })
        doc: dict[str, Any] = {
            "verdict": self.verdict,
            "findings": findings,
            # each with why it was not named (the judge's reasons; none for the named one)
            "candidates": [{**c.to_json(), "not_named": self.judgement.reasons.get(f"{c.effect}@{c.target}", [])}
                           for c in self.candidates],
            "where": self.where.to_json(),
            "patch": {"source": getattr(self.patch, "source", None), "model": getattr(self.patch, "model", None),
                      "fmu": str(self.patch_fmu) if self.patch_fmu else None,
                      "spec": str(self.patch_spec) if self.patch_spec else None},
            "seconds": float(self.seconds),
            "timings": {k: v.to_json() for k, v in self.timings.items()},
        }
        if self.verdict == "unexplained":
            doc["unexplained"] = {t: [list(p) for p in ps] for t, ps in self.judgement.unexplained.items()}
        if self.where.balances:
            doc["balances"] = [b.to_json() for b in self.where.balances]
        doc["null"] = {"parameters": dict(self.where.null.parameters),
                       "validation_nrmse": dict(self.where.null.validation_nrmse)}
        return doc


def _num(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def _effect_folders(spec: Any) -> tuple[str, ...]:
    table = getattr(spec, "diagnose", None)
    folders = getattr(table, "effects", None) if table is not None else None
    return tuple(str(f) for f in folders or ())


def diagnose(spec: Any, settings: DiagnoseSettings = DiagnoseSettings(), *, progress: Progress | None = None,
             null: Any = None) -> DiagnosisResult:
    """Find where the twin and the measurements disagree, which effect explains it, and patch the twin.

    Parameters
    ----------
    spec
        A loaded spec (with ``[source]`` for process effects and patches).
    settings
        :class:`DiagnoseSettings`.
    progress
        ``progress(stage, done, total)``.
    null
        An existing estimate of the spec's candidates (skips the null fit).

    Returns
    -------
    DiagnosisResult

    Raises
    ------
    SpecError, DataError, FMUError, EstimationError, CompileError
    """
    if settings.scheduler == "local":  # one local cluster for every phase, reached through its address
        cluster = make_executor("local", settings.workers or 2)
        try:
            return diagnose(spec, replace(settings, scheduler=cluster.cluster.scheduler_address),
                            progress=progress, null=null)
        finally:
            cluster.shutdown()
    # the measurement file is laid on windows by every candidate's spec: parsed once
    with kept_tables():
        return _diagnosed(spec, settings, progress, null)


def _diagnosed(spec: Any, settings: DiagnoseSettings, progress: Progress | None, null: Any) -> DiagnosisResult:
    """:func:`diagnose` once its cluster is up."""
    t0 = time.perf_counter()
    clock = _Clock()
    clock.start("null")
    effects = library.load_effects(_effect_folders(spec))
    unknown = [e for e in settings.effects if e not in effects]
    if unknown:
        raise SpecError("; ".join(f"unknown effect {e!r}{did_you_mean(e, sorted(effects))}" for e in unknown))
    if progress is not None:
        progress("null", 0, 1)
    n_candidates = len(list(spec.parameters))
    workers = settings.workers
    if workers is None:
        workers = min(2, os.cpu_count() or 1) if n_candidates > 3 else 1
    # the screening's jobs are independent whatever the number of candidates
    screen_workers = settings.workers if settings.workers is not None else min(2, os.cpu_count() or 1)
    grid = settings.grid if settings.grid is not None else (60.0 if n_candidates > 3 else None)
    scheduler = settings.scheduler if workers > 1 else None
    options = {"seed": settings.seed, "workers": workers, "scheduler": scheduler,
               "maxiter": 0 if settings.maxiter is None else settings.maxiter, "warmup": settings.warmup,
               "refine_grid": grid or None, "jacobian": settings.jacobian,
               "refine_iterations": settings.null_iterations or iterations_for(n_candidates, NULL_RUNS)}
    with pool(workers, scheduler):
        # the null's series and output Jacobian: 1 + n independent runs per window
        found = where(spec, null=null, estimate_options=options, varying_step=settings.varying_step)
    if progress is not None:
        progress("null", 1, 1)

    tmp = None
    work = settings.work_dir or (Path(settings.out_dir) / "work" if settings.out_dir else None)
    if work is None and (settings.compile or settings.out_dir):
        tmp = tempfile.TemporaryDirectory(prefix="tbx-diagnose-")
        work = Path(tmp.name)
    try:
        # a candidate's fit estimates the spec's candidates and (mostly) one or two effect parameters
        budget = FitBudget(maxiter=0, refine_iterations=settings.fit_iterations
                           or iterations_for(n_candidates + 1, FIT_RUNS, most=8), workers=workers,
                           warmup=settings.warmup, grid=grid or None, scheduler=scheduler,
                           jacobian=settings.jacobian)
        clock.start("screen")
        # the ramps' searches and the compiled patches are screening jobs of their own, spread over
        # screen_workers (they do not depend on each other); the sensor transforms run here meanwhile
        with pool(screen_workers, settings.scheduler):
            screened = screen(effects, spec, found, compiled_in=work if settings.compile else None,
                              only=settings.effects, progress=progress, exclude=settings.exclude,
                              relinearise=(settings.relinearise if settings.relinearise is not None
                                           else 3 if n_candidates <= 3 else 1))
        ranked = list(screened)
        if settings.compile:
            samples = validation_samples(found)
            eligible = [c for c in screened if c.stage != "skipped" and c.fit is None
                        and math.isfinite(c.delta_bic) and c.delta_bic > settings.fit_min_delta_bic]
            # a candidate whose screening already passes the judge's tests is fitted before one whose
            # screening does not (stable: each group keeps its ΔBIC order); on a twin that misses more
            # than the hidden effect (heat production's linear laws) candidates that absorb the mismatch
            # on training (fouling ramps there) out-score the one that passes on validation
            passes = {id(c): not objections(c, found, samples) for c in eligible}
            fitted: dict[tuple[str, str], Candidate] = {}
            clock.start("fit")
            assert work is not None
            for _ in range(max(settings.fit_rounds, 1)):
                done = [(c, not objections(f, found, samples)) for c in eligible
                        if (f := fitted.get((c.effect, c.target))) is not None]
                best = next_fits(eligible, passes, done, settings.fit_best)
                if not best:
                    break
                # two or more fits run side by side, one process each (the same runs as one after the other
                # with their Jacobians spread over the workers, but their serial parts overlap too); a single
                # fit keeps the workers for its Jacobian
                side_by_side = len(best) > 1 and screen_workers > 1
                one = replace(budget, workers=1, scheduler=None) if side_by_side else budget
                total = len(fitted) + len(best)
                with pool(min(screen_workers, len(best)) if side_by_side else 1, settings.scheduler):
                    results = [submit(fit_job, (spec, found, effects[c.effect], c, work, one)) for c in best]
                    for c, result in zip(best, results):
                        fitted[(c.effect, c.target)] = result()
                        if progress is not None:
                            progress("fit", len(fitted), total)
            # a fitted candidate replaces its screening; with compile only fitted candidates can be named
            ranked = rank([fitted.get((c.effect, c.target), c) for c in screened])
        clock.start("judge")
        nameable = [c for c in ranked if c.fit is not None] if settings.compile else ranked
        judgement = judge(nameable, found)
        if settings.compile:
            samples = min((r.samples for r in found.validation_tags.values()), default=0)
            for c in ranked:
                key = f"{c.effect}@{c.target}"
                if c.fit is None and key not in judgement.reasons:
                    judgement.reasons[key] = reasons_against(c, samples) or [
                        "passes its screening but was not fitted (with --compile only fitted candidates are named)"]
        named = judgement.named
        patch = patch_fmu = patch_spec = patch_file = None
        if named is not None and spec.source is not None:
            clock.start("patch")
            patch, patch_fmu, patch_spec, patch_file = _patch(spec, effects[named.effect], named, settings, work)
        elif named is not None:
            log.warning("the spec has no [source]: the named effect is not rendered into a patch")
    finally:
        if tmp is not None and not settings.out_dir:
            # the fitted FMU lives only as long as this call when no output folder is given
            tmp.cleanup()
            patch_fmu_alive = False
        else:
            patch_fmu_alive = True
    if not patch_fmu_alive:
        patch_fmu = patch_spec = None
    clock.stop()
    for phase, t in clock.phases.items():
        log.info("phase %s: %.1f s wall, %.1f s CPU", phase, t.wall, t.cpu)
    return DiagnosisResult(judgement.verdict, named, tuple(ranked), found, judgement, patch, patch_fmu, patch_spec,
                           patch_file, time.perf_counter() - t0,
                           {k: getattr(v, "explanation", "") for k, v in effects.items()}, dict(clock.phases))


def next_fits(eligible: Sequence[Candidate], passes: Mapping[int, bool],
              done: Sequence[tuple[Candidate, bool]], fit_best: int) -> list[Candidate]:
    """The screened candidates to fit in the next round (empty: stop fitting).

    Parameters
    ----------
    eligible
        Screened candidates worth a fit, best ΔBIC first.
    passes
        ``id(candidate)`` -> whether its screening passes the judge's tests.
    done
        The candidates fitted so far, each with whether its fit passes.
    fit_best
        Fits a round (the first round may add one, below).

    The first round takes the *fit_best* first candidates, those whose screening passes
    before the others (each group keeps its order), and the candidate the training data
    favour most (the first of *eligible*) where it is not among them: a screening is a
    linearised or ramped approximation, and one that fails the judge's tests on a detail
    (a tag made slightly worse, a ramp that overshoots on validation) may pass when fitted
    properly. Another round is worth it only while no fit passes, and takes only
    candidates whose screening passes.

    Examples
    --------
    >>> a, b, c, d = "abcd"   # any objects stand for candidates here
    >>> ok = {id(a): False, id(b): True, id(c): True, id(d): False}
    >>> next_fits([a, b, c, d], ok, [], 2)
    ['b', 'c', 'a']
    >>> next_fits([b, c, a, d], ok, [], 2)
    ['b', 'c']
    >>> next_fits([a, b, c, d], {id(a): False, id(b): True, id(c): False, id(d): False}, [], 2)
    ['b', 'a']
    >>> next_fits([a, b, c, d], {**ok, id(d): True}, [(b, False), (c, False), (a, False)], 2)
    ['d']
    >>> next_fits([a, b, c, d], {**ok, id(d): True}, [(b, True), (c, False)], 2)
    []
    >>> next_fits([a, b, c, d], ok, [(b, False), (c, False)], 2)
    []
    """
    fitted = {id(c) for c, _ in done}
    if not done:
        first = [c for c in eligible if passes.get(id(c), False)]
        picked = (first + [c for c in eligible if not passes.get(id(c), False)])[:fit_best]
        if eligible and fit_best > 0 and all(c is not eligible[0] for c in picked):
            picked.append(eligible[0])
        return picked
    if any(ok for _, ok in done):
        return []
    return [c for c in eligible if passes.get(id(c), False) and id(c) not in fitted][:fit_best]


def _patch(spec: Any, effect: Any, named: Candidate, settings: DiagnoseSettings,
           work: Path | None) -> tuple[Any, Path | None, Path | None, Path | None]:
    """Render the named effect; compile and write it as the settings ask."""
    if named.fit is not None:
        outcome = named.fit
        bounds = {_short(p.name, effect): (float(p.min), float(p.max)) for p in outcome.patch.parameters}
        values = {s: min(max(named.values.get(s, v), bounds.get(s, (-math.inf, math.inf))[0]),
                         bounds.get(s, (-math.inf, math.inf))[1])
                  for s, v in warm_values(effect, None, None, {_short(p.name, effect): p.start
                                                                for p in outcome.patch.parameters}).items()}
        patch = render(spec, effect, named.target, values)
        fmu = outcome.fmu
    else:
        first = render(spec, effect, named.target, {})
        bounds = {_short(p.name, effect): (float(p.min), float(p.max)) for p in first.parameters}
        patch = render(spec, effect, named.target, warm_values(effect, named, bounds,
                                                               {_short(p.name, effect): p.start for p in first.parameters}))
        fmu = None
        if settings.compile or settings.out_dir:
            assert work is not None
            folder = Path(work) / "named"
            folder.mkdir(parents=True, exist_ok=True)
            fmu = Path(library.compile_patch(
                patch, folder, libraries=spec.source.libraries if spec.source is not None else ()).fmu)
    patch_file = patch_spec = None
    if settings.out_dir is not None:
        out = Path(settings.out_dir)
        out.mkdir(parents=True, exist_ok=True)
        written = library.write_patch(patch, out)
        patch_file = Path(written) if written is not None else None
        if fmu is not None:
            target = out / f"{patch.model.rsplit('.', 1)[-1]}.fmu"
            shutil.copyfile(fmu, target)
            fmu = target
            patch_spec = Path(library.patched_spec(spec, patch, out, fmu))
    return patch, fmu, patch_spec, patch_file
