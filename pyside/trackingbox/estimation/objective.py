"""The estimation's cost: the NRMSE of a parameter set over a window (:class:`Objective`), its residuals
and Jacobian (finite differences or the sensitivity equations: :func:`jacobian_support` says which).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import config
from ..errors import (
    EstimationError,
    TrackingError,
)
from ..native import NativeUnavailable, native_reason
from ..sensitivity import support
from ..simulation.models import cached_model
from ..simulation.windows import (
    Problem,
    WindowData,
    run_start,
    simulate_window,
    simulate_window_sensitivities,
    window_setup,
)
from .settings import DIFF_STEP, FAILED_COST, JACOBIAN_METHODS

log = logging.getLogger(__name__)


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
    return float(np.sqrt(np.mean(err * err)) / scale(meas[ok]))


def scale(values: np.ndarray) -> float:
    span = float(np.max(values) - np.min(values))
    if span > 0.0:
        return span
    return max(abs(float(np.mean(values))), 1.0)


class Objective:
    """The cost on one window: callable on a parameter vector, picklable.

    Parameters
    ----------
    problem
        The estimation problem.
    window
        The window whose measurements the simulation is compared with.
    history
        The windows a carried state comes from (``problem.carry``, :func:`.windows.carried_states`).
    """

    def __init__(self, problem: Problem, window: WindowData, history: tuple[WindowData, ...] = ()) -> None:
        self.problem = problem
        self.window = window
        self.history = tuple(history)
        tags = list(problem.outputs)
        self._valid = {tag: np.isfinite(window.measured[tag]) for tag in tags}
        self._scale = {tag: scale(window.measured[tag][self._valid[tag]]) for tag in tags}
        n_tags = len(tags)
        self._weight = {
            tag: 1.0 / (self._scale[tag] * math.sqrt(self._valid[tag].sum() * n_tags)) for tag in tags
        }
        self._size = int(sum(v.sum() for v in self._valid.values()))

    def nrmse(self, x: npt.ArrayLike) -> dict[str, float]:
        """NRMSE per output tag at *x* (raises SimulationError if the twin fails)."""
        sim = simulate_window(self.problem, self.window, x, history=getattr(self, "history", ()))
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
            log.warning("simulation failed at %s: %s", fmt_values(self.problem.names, x), exc)
            return FAILED_COST

    def residuals(self, x: npt.ArrayLike, tag_weights: Mapping[str, float] | None = None) -> np.ndarray:
        """Weighted residual vector; its sum of squares is the mean of NRMSE**2.

        With *tag_weights*, each tag's residuals are multiplied by the square root
        of its weight (the sum of squares becomes the weighted mean of NRMSE**2).
        """
        try:
            sim = simulate_window(self.problem, self.window, x, history=getattr(self, "history", ()))
        except (TrackingError, ArithmeticError) as exc:
            log.warning("simulation failed at %s: %s", fmt_values(self.problem.names, x), exc)
            return np.full(self._size, FAILED_COST / math.sqrt(max(self._size, 1)))
        parts = []
        for tag, y in sim.items():
            ok = self._valid[tag]
            w = self._weight[tag] * (math.sqrt(tag_weights[tag]) if tag_weights else 1.0)
            parts.append((y[ok] - self.window.measured[tag][ok]) * w)
        return np.concatenate(parts)


def residuals_and_jacobian(objective: Objective, x: npt.ArrayLike,
                            tag_weights: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Objective.residuals` and its exact Jacobian w.r.t. *x* from one sensitivity run.

    A failed run gives the failed residuals (as :meth:`Objective.residuals`) and a zero Jacobian.
    """
    problem = objective.problem
    try:
        sim, slopes = simulate_window_sensitivities(problem, objective.window, x)
    except (TrackingError, ArithmeticError) as exc:
        log.warning("sensitivity run failed at %s: %s", fmt_values(problem.names, x), exc)
        size = objective._size
        return (np.full(size, FAILED_COST / math.sqrt(max(size, 1))), np.zeros((size, len(problem.names))))
    parts, rows = [], []
    for tag, y in sim.items():
        ok = objective._valid[tag]
        w = objective._weight[tag] * (math.sqrt(tag_weights[tag]) if tag_weights else 1.0)
        parts.append((y[ok] - objective.window.measured[tag][ok]) * w)
        rows.append(slopes[tag][ok] * w)
    return np.concatenate(parts), np.concatenate(rows, axis=0)


class ExactResiduals:
    """Picklable ``x -> [residuals, Jacobian.ravel()]`` (one flat array, as the journal records it)."""

    def __init__(self, objective: Objective, weights: Mapping[str, float] | None) -> None:
        self.objective = objective
        self.weights = dict(weights) if weights else None

    def __call__(self, x: npt.ArrayLike) -> np.ndarray:
        r, jac = residuals_and_jacobian(self.objective, x, self.weights)
        return np.concatenate([r, jac.ravel()])

    def split(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The residuals and the Jacobian back from :meth:`__call__`'s array."""
        size = self.objective._size
        return flat[:size], flat[size:].reshape(size, -1)


def runs_native(model: Any) -> bool:
    """True if *model*'s runs go through the native stepper (what :meth:`FMUModel.stepper` chooses by default)."""
    if not config.get("native"):
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
    if requested not in JACOBIAN_METHODS:
        raise EstimationError(f"jacobian must be one of {', '.join(JACOBIAN_METHODS)}, not {requested!r}")
    if requested == "fd":
        return "fd", "requested"
    model = cached_model(problem.twin)
    if requested == "auto" and runs_native(model):
        why = (f"{Path(problem.twin).name} runs on the native stepper, the sensitivity equations do not: "
               "1 + n native runs are the cheaper Jacobian")
        log.info("refinement Jacobian by finite differences: %s", why)
        return "fd", why
    if problem.initial != "model":
        why = (f"runs start from the steady state ([data] initial = {problem.initial!r}), which moves with the "
               "parameters; the sensitivity equations start at zero")
        if requested == "exact":
            raise EstimationError(f"jacobian = 'exact' is not possible: {why}; use 'fd' or 'auto'")
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


class ResidualTask:
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


def fmt_values(names: Sequence[str], x: npt.ArrayLike) -> str:
    return ", ".join(f"{n}={v:.6g}" for n, v in zip(names, np.atleast_1d(np.asarray(x, dtype=float))))
