"""The estimation's two searches: differential evolution over the bounds (:func:`global_search`) and the
bounded least-squares refinement from its best point (:func:`refine_estimate`).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.optimize import differential_evolution, least_squares

from ..checkpoint import Journal
from ..errors import (
    TrackingError,
)
from ..simulation.windows import (
    Problem,
)
from .objective import (
    ExactResiduals,
    Objective,
    ResidualTask,
    fmt_values,
    jacobian_points,
)
from .settings import (
    DEFAULT_GLOBAL_EVALUATIONS,
    DEFAULT_MAXITER,
    DEFAULT_POPULATION,
    FAILED_COST,
    GLOBAL_SETTLE,
    REFINE_STEP_TOLERANCE,
    ProgressCallback,
)

log = logging.getLogger(__name__)


def default_maxiter(n_parameters: int, popsize: int | None = None) -> int:
    """Default number of generations: :data:`DEFAULT_MAXITER`, capped by the simulation budget.

    With ``P`` individuals in all, at most ``DEFAULT_GLOBAL_EVALUATIONS // P - 1``
    generations (at least 2): 30 for one parameter (population 15), 16 for
    fourteen (population 28).

    >>> default_maxiter(1), default_maxiter(14)
    (30, 16)
    """
    population = population_per_parameter(n_parameters, popsize) * n_parameters
    return max(2, min(DEFAULT_MAXITER, DEFAULT_GLOBAL_EVALUATIONS // population - 1))


def population_per_parameter(n: int, popsize: int | None) -> int:
    """Population per parameter handed to differential evolution (total at least 5)."""
    return max(popsize or max(2, math.ceil(DEFAULT_POPULATION / n)), math.ceil(5 / n))


def global_search(train: Objective, coarse: Objective, problem: Problem, pool: Any, journal: Journal, *, seed: int,
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
    n = len(problem.names)
    best_x, best_cost = best
    per_parameter = population_per_parameter(n, popsize)
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
            extent = better_half_extent(intermediate_result, span)
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
             de.nit, " (settled)" if settled else "", de.nfev, len(scored), best_cost, fmt_values(problem.names, best_x))
    return best_x, best_cost, int(de.nfev) + len(scored)


def better_half_extent(intermediate_result: Any, span: np.ndarray) -> float:
    """Largest extent, over the parameters, of the better half of a DE population, in parts of the ranges."""
    population = np.asarray(getattr(intermediate_result, "population", ()), dtype=float)
    energies = np.asarray(getattr(intermediate_result, "population_energies", ()), dtype=float)
    if population.ndim != 2 or population.shape[0] != energies.size or energies.size < 2:
        return math.inf
    better = population[np.argsort(energies, kind="stable")[:max(2, energies.size // 2)]]
    return float(np.max((better.max(axis=0) - better.min(axis=0)) / span))


def refine_estimate(train: Objective, problem: Problem, pool: Any, journal: Journal, *, best: tuple[np.ndarray, float], iterations: int,
            progress: ProgressCallback | None, label: str = "",
            checkpoint: Callable[[int, np.ndarray, float, int], None],
            jacobian: str = "fd") -> tuple[np.ndarray, float, int]:
    """Bounded least squares (trust-region reflective) from *best*; returns best x, cost, evaluations.

    With *jacobian* ``"fd"`` the Jacobian is a forward difference on all parameters
    (:func:`jacobian_points`), its ``n`` simulations spread over *pool*; with
    ``"exact"`` every residual evaluation is a sensitivity run that also gives the
    Jacobian (:func:`exact_functions`). With several output tags a second pass
    reweights each tag by ``1 / NRMSE_tag`` at the first pass's point (iteratively
    reweighted least squares), which makes the weighted mean of ``NRMSE**2`` agree with
    the mean NRMSE there in value and gradient. A pass's point is kept only if its mean
    NRMSE is not above the best so far.
    """
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
        task = ResidualTask(train, weights)
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
            fun, jac = exact_functions(ExactResiduals(train, weights), journal, label + f"exact{k}", record)
        else:
            fun = fd_fun
            jac = fd_jacobian(fun, last, task, problem, pool, journal, label + f"residuals{k}", record)
        jac, stop = step_stop(jac, problem)
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


def step_stop(jac: Callable[[np.ndarray], np.ndarray], problem: Problem
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
                      fmt_values(problem.names, moved), REFINE_STEP_TOLERANCE)
            raise StopIteration

    return remembering, stop


def fd_jacobian(fun: Callable[[np.ndarray], np.ndarray], last: dict[str, Any], task: ResidualTask, problem: Problem,
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


def exact_functions(task: ExactResiduals, journal: Journal, label: str,
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
