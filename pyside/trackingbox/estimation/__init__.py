"""Bounded gray-box estimation of a twin's parameters from measurements (the estimate stage's computation).

Modules: :mod:`.stage` (:func:`estimate`, the result, the run with its journal and checkpoint),
:mod:`.search` (differential evolution, then the least-squares refinement), :mod:`.objective`
(the cost, its residuals and Jacobian), :mod:`.settings` (defaults and budgets). The twin's runs
over a window are the simulation service's (:mod:`trackingbox.simulation.windows`); their names
are importable from here too, as they always were.
"""
from __future__ import annotations

from ..simulation.models import close_models
from ..simulation.windows import (
    DEFAULT_WARMUP,
    MIN_VALID_SAMPLES,
    Problem,
    WindowData,
    coarsen,
    load_windows,
    problem_from_spec,
    run_start,
    simulate_window,
    simulate_window_sensitivities,
    window_setup,
)
from .objective import Objective, jacobian_points, jacobian_support, nrmse
from .search import default_maxiter
from .settings import (
    DEFAULT_GLOBAL_EVALUATIONS,
    DEFAULT_GLOBAL_GRID,
    DEFAULT_MAXITER,
    DEFAULT_POPULATION,
    GLOBAL_SETTLE,
    JACOBIAN_METHODS,
    MAX_REFINE_ITERATIONS,
    ProgressCallback,
)
from .stage import EstimationResult, estimate, fit_series, journal_path, write_starts

__all__ = [
    "EstimationResult", "estimate", "fit_series", "write_starts", "nrmse", "jacobian_points", "jacobian_support",
    "default_maxiter", "journal_path", "Objective", "Problem", "WindowData", "coarsen", "load_windows",
    "problem_from_spec", "run_start", "simulate_window", "simulate_window_sensitivities", "window_setup",
    "close_models", "DEFAULT_WARMUP", "MIN_VALID_SAMPLES", "DEFAULT_MAXITER", "DEFAULT_GLOBAL_EVALUATIONS",
    "DEFAULT_POPULATION", "DEFAULT_GLOBAL_GRID", "GLOBAL_SETTLE", "MAX_REFINE_ITERATIONS", "JACOBIAN_METHODS",
    "ProgressCallback",
]
