"""Sobol variance-based sensitivity of the twin's steady state to the candidate parameters.

Saltelli sampling (SALib's Sobol' sequence) over the parameter bounds; each
sample is a steady-state run of the twin with its controllers frozen (the same
procedure as the step tests, :mod:`~trackingbox.analysis.steptest`), run in
parallel through an executor. It needs ``N * (D + 2)`` runs for ``D``
parameters, far more than the ``2 D`` step tests of the RGA, and serves as a
cross-check of the RGA pairing (:func:`agreement`).
"""
from __future__ import annotations

import logging
import math
import time as _time
import warnings
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from ..errors import AnalysisError
from .pairing import Pairing
from .steptest import (
    Progress,
    RunPlan,
    StepProblem,
    StepSettings,
    baseline,
    default_ranges,
    run_against_reference,
)

logger = logging.getLogger(__name__)

Index = Literal["first", "total"]


@dataclass(frozen=True)
class SobolResult:
    """First-order and total Sobol indices, rows = variables, columns = parameters.

    Attributes
    ----------
    variables, parameters : tuple of str
    first, total : ndarray, shape (m, n)
        First-order (``S1``) and total-effect (``ST``) indices; 0 for an output
        that does not vary at all.
    first_conf, total_conf : ndarray, shape (m, n)
        Half-widths of SALib's bootstrap 95 % confidence intervals.
    samples : int
        Base sample size ``N``.
    runs : int
        Model evaluations ``N * (D + 2)``.
    seconds : float
        Wall-clock time.
    """

    variables: tuple[str, ...]
    parameters: tuple[str, ...]
    first: np.ndarray = field(repr=False, compare=False)
    total: np.ndarray = field(repr=False, compare=False)
    first_conf: np.ndarray = field(repr=False, compare=False)
    total_conf: np.ndarray = field(repr=False, compare=False)
    samples: int = 0
    runs: int = 0
    seconds: float = 0.0

    def choice(self, index: Index = "total", min_index: float = 0.05) -> dict[str, str]:
        """One parameter per variable, no parameter twice, maximising the summed index.

        Parameters
        ----------
        index : {"total", "first"}
        min_index : float
            Assignments whose index is below this are dropped (the parameter
            explains almost none of the variable's variance).

        Returns
        -------
        dict
            Variable -> parameter, for at most ``min(m, n)`` variables.
        """
        S = np.nan_to_num(self.total if index == "total" else self.first, nan=0.0)
        rows, cols = linear_sum_assignment(-S)
        return {self.variables[i]: self.parameters[j] for i, j in zip(rows, cols)
                if S[i, j] >= min_index and S[i, j] > 0}


def _problem_dict(names: Sequence[str], lower: Sequence[float], upper: Sequence[float]) -> dict:
    return {"num_vars": len(names), "names": list(names),
            "bounds": [[float(lo), float(hi)] for lo, hi in zip(lower, upper)]}


def sample_parameters(names: Sequence[str], lower: Sequence[float], upper: Sequence[float], n: int, *,
                      seed: int | None = 0) -> np.ndarray:
    """Saltelli sample (first and total order only) of shape ``(n * (D + 2), D)``.

    Parameters
    ----------
    names : sequence of str
    lower, upper : sequence of float
        Bounds of each parameter.
    n : int
        Base sample size, a power of two.
    seed : int, optional
        Scrambling seed (reproducible samples).

    Raises
    ------
    AnalysisError
        If *n* is not a power of two or the bounds are empty.
    """
    # deferred (start-up): SALib adds 0.37-0.51 s to an import of the package (python -X importtime); only
    # the Sobol method needs it
    from SALib.sample import sobol as sobol_sample

    if n < 2 or n & (n - 1):
        raise AnalysisError(f"Sobol base sample size must be a power of two (>= 2), got {n}")
    for name, lo, hi in zip(names, lower, upper):
        if not hi > lo:
            raise AnalysisError(f"parameter {name!r} has bounds [{lo:g}, {hi:g}]: min must be below max")
    return sobol_sample.sample(_problem_dict(names, lower, upper), n, calc_second_order=False, seed=seed)


def indices_from_outputs(variables: Sequence[str], names: Sequence[str], lower: Sequence[float],
                         upper: Sequence[float], Y: npt.ArrayLike, n: int, *, seed: int | None = 0,
                         seconds: float = 0.0) -> SobolResult:
    """Sobol indices of each column of *Y* (rows in :func:`sample_parameters` order).

    Parameters
    ----------
    variables : sequence of str
        Names of the columns of *Y*.
    names, lower, upper : sequence
        Parameters and bounds the sample was drawn from.
    Y : array_like, shape (n * (D + 2), m)
        Model outputs.
    n : int
        Base sample size.
    seed : int, optional
        Bootstrap seed of the confidence intervals.

    Returns
    -------
    SobolResult
    """
    # deferred (start-up): SALib adds 0.37-0.51 s to an import of the package (python -X importtime); only
    # the Sobol method needs it
    from SALib.analyze import sobol as sobol_analyze

    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    D = len(names)
    if Y.shape[0] != n * (D + 2) or Y.shape[1] != len(variables):
        raise AnalysisError(f"Sobol outputs have shape {Y.shape}; expected ({n * (D + 2)}, {len(variables)})")
    m = Y.shape[1]
    S1, ST, C1, CT = (np.zeros((m, D)) for _ in range(4))
    prob = _problem_dict(names, lower, upper)
    for i in range(m):
        y = Y[:, i]
        if not np.all(np.isfinite(y)):
            raise AnalysisError(f"Sobol outputs of {variables[i]!r} contain non-finite values")
        if np.ptp(y) <= 1e-12 * max(1.0, float(np.abs(y).max())):
            logger.info("%s does not vary over the parameter bounds: indices set to 0", variables[i])
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            res = sobol_analyze.analyze(prob, y, calc_second_order=False, seed=seed)
        S1[i], ST[i], C1[i], CT[i] = res["S1"], res["ST"], res["S1_conf"], res["ST_conf"]
    return SobolResult(tuple(variables), tuple(names), S1, ST, C1, CT, samples=n, runs=int(Y.shape[0]),
                       seconds=seconds)


def sobol_indices(problem: StepProblem, settings: StepSettings = StepSettings(), *, n: int = 32,
                  seed: int | None = 0, executor: Executor | None = None,
                  progress: Progress | None = None) -> SobolResult:
    """Sobol indices of the twin's steady-state outputs over the parameter bounds.

    Each sample sets all parameters at the baseline's step time (controllers
    frozen as in the step tests) and records the outputs once they settle.

    Parameters
    ----------
    problem : StepProblem
    settings : StepSettings
        Settle rule and freeze values (``step`` is not used).
    n : int
        Base sample size (power of two); ``n * (D + 2)`` runs.
    seed : int, optional
    executor : concurrent.futures.Executor, optional
        Serial in this process when omitted.
    progress : callable, optional
        ``progress(done, total)`` after each sample.

    Returns
    -------
    SobolResult

    Raises
    ------
    AnalysisError
        If a sample does not settle or a simulation fails.
    """
    t_wall = _time.perf_counter()
    if not all(math.isfinite(r) and r > 0 for r in problem.ranges) or len(problem.ranges) != len(problem.outputs):
        problem = replace(problem, ranges=default_ranges(problem, settings))
    X = sample_parameters(problem.parameters, problem.lower, problem.upper, n, seed=seed)
    logger.info("Sobol: %d runs (N = %d, %d parameters)", X.shape[0], n, len(problem.parameters))
    if settings.reference_horizon is None:
        # one reference over the whole max_time, not the step tests' shorter first one: a sample moves
        # every parameter at once, anywhere in its bounds, and settles more slowly than a 5 % step; a
        # sample that runs past the reference is run again from the start. On the 7-effect evaporator
        # train (22 candidates, N = 32) every one of the 768 samples ran past the 3 h first reference,
        # and all were run again (47 min of a loaded 2-core machine lost), where the longer reference costs
        # one simulated day of the twin.
        settings = replace(settings, reference_horizon=settings.max_time)
    base = baseline(problem, settings, executor)
    plans = [RunPlan(problem.fmu, problem.start_values(), problem.outputs, problem.ranges, settings,
                     base.freeze_time, base.step_time, tuple(zip(problem.parameters, map(float, x))),
                     label=f"Sobol sample {k}", states=base.states, compensation=problem.compensation,
                     levels_ref=base.levels_ref)
             for k, x in enumerate(X)]
    _, results, _ = run_against_reference(problem, settings, base, plans, executor, progress)
    Y = np.array([r.after for r in results])
    return indices_from_outputs(problem.variables, problem.parameters, problem.lower, problem.upper, Y, n,
                                seed=seed, seconds=_time.perf_counter() - t_wall)


@dataclass(frozen=True)
class Agreement:
    """Where the RGA pairing and the Sobol ranking choose the same parameter.

    Attributes
    ----------
    rows : tuple of (variable, rga parameter or None, sobol parameter or None, same)
        One row per variable of the Sobol result.
    agree : int
        Variables for which both chose the same parameter.
    compared : int
        Variables for which both chose a parameter.
    index : str
        Which Sobol index ranked the parameters.
    """

    rows: tuple[tuple[str, str | None, str | None, bool], ...]
    agree: int
    compared: int
    index: str = "total"

    @property
    def fraction(self) -> float:
        """``agree / compared`` (NaN when nothing was compared)."""
        return self.agree / self.compared if self.compared else math.nan


def agreement(rga_pairing: Pairing, sobol: SobolResult, *, index: Index = "total") -> Agreement:
    """Compare the RGA pairing with the Sobol choice (:meth:`SobolResult.choice`).

    Parameters
    ----------
    rga_pairing : Pairing
    sobol : SobolResult
    index : {"total", "first"}

    Returns
    -------
    Agreement
    """
    choice = sobol.choice(index)
    rows = []
    agree = compared = 0
    for v in sobol.variables:
        a = rga_pairing.parameter_for(v)
        b = choice.get(v)
        same = a is not None and a == b
        if a is not None and b is not None:
            compared += 1
            agree += int(same)
        rows.append((v, a, b, same))
    return Agreement(tuple(rows), agree, compared, index)
