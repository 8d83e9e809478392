"""The estimate stage: bounded gray-box estimation of the spec's ``[[parameters]]`` on its training window.

``run(spec, EstimateSettings(...), progress=...)`` -> :class:`~trackingbox.estimation.EstimationResult`
(the computation: :func:`trackingbox.estimation.estimate`, whose keywords are the settings' fields).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..estimation import (
    GLOBAL_SETTLE,
    MAX_REFINE_ITERATIONS,
    EstimationResult,
    ProgressCallback,
    estimate,
)
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
    """Estimate the spec's parameters with *settings*; *progress* gets the generations and refinement steps."""
    return estimate(spec, **{f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)},
                    progress=None if progress is None else progress_lines(progress))
