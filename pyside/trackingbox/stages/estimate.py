"""The estimate stage: bounded gray-box estimation of the spec's ``[[parameters]]`` on its training window.

``run(spec, EstimateSettings(...), progress=...)`` -> :class:`~trackingbox.estimation.EstimationResult`
(the computation: :func:`trackingbox.estimation.estimate`, whose keywords are the settings' fields but
``level`` and ``identify``): before it, what the data can determine at the start values (a warning per
group of parameters they cannot tell apart: :func:`trackingbox.identify.hooks.before_estimate`); after
it, the confidence intervals at the estimate (:func:`trackingbox.identify.hooks.after_estimate`).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import EstimationError
from ..estimation import (
    GLOBAL_SETTLE,
    MAX_REFINE_ITERATIONS,
    EstimationResult,
    ProgressCallback,
    estimate,
)
from ..identify.hooks import after_estimate, before_estimate
from .contract import Progress


@dataclass(frozen=True)
class EstimateSettings:
    """Settings of the estimate stage (the ``trackingbox estimate`` options; see :func:`~trackingbox.estimation.estimate`)."""

    seed: int = 0
    workers: int | None = None
    scheduler: str | None = None
    maxiter: int | None = None
    popsize: int | None = None
    warmup: float | None = None
    refine: bool = True
    refine_iterations: int = MAX_REFINE_ITERATIONS
    checkpoint: Path | None = None
    global_grid: float | None = None
    resume: bool = False
    refine_grid: float | None = None
    jacobian: str = "auto"
    settle: float = GLOBAL_SETTLE
    level: float | None = 0.95
    identify: bool = True

    #: fields that are not the computation's keywords: what the data determine, checked around it
    AROUND = ("level", "identify")


def progress_lines(progress: Progress) -> ProgressCallback:
    """The estimation's ``(stage, iteration, total, best_cost)`` reports as :class:`Progress` calls."""

    def report(stage: str, iteration: int, total: int, best: float) -> None:
        if stage == "global":
            progress("global search", iteration, total, f"best NRMSE {best:.5g}", unit="generation")
        elif stage == "refine":
            progress("refinement", iteration, total, f"rms NRMSE {best:.5g}", unit="simulation")
        else:
            progress("refinement done", 1, 1, f"NRMSE {best:.5g}")

    return report


def run(spec: Any, settings: EstimateSettings = EstimateSettings(), *,
        progress: Progress | None = None) -> EstimationResult:
    """Estimate the spec's parameters with *settings*; *progress* gets the identifiability check's points,
    the generations and refinement steps, and the interval profiles' runs.

    ``settings.identify``: check what the data can determine at the start values first (warnings);
    ``settings.level``: the confidence level of the intervals at the estimate (None: none).
    """
    level = settings.level
    if level is not None and not (isinstance(level, (int, float)) and 0.0 < float(level) < 1.0):
        raise EstimationError(f"estimate: level must be a fraction in (0, 1), not {level!r}")
    points = None if progress is None else (
        lambda stage, done, total: progress(f"identifiability ({stage})", done, total, unit="point"))
    before = (before_estimate(spec, warmup=settings.warmup, jacobian=settings.jacobian, progress=points)
              if settings.identify else None)
    result = estimate(spec, **{f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)
                               if f.name not in EstimateSettings.AROUND},
                      progress=None if progress is None else progress_lines(progress))
    runs = None if progress is None else (
        lambda done, total: progress("intervals", done, total, "profile likelihood", unit="run"))
    return after_estimate(spec, result, before, level=level, warmup=settings.warmup, jacobian=settings.jacobian,
                          progress=runs)
