"""The twin on one window of data: residuals and output sensitivities w.r.t. the estimated parameters.

A thin layer over the estimation's problem (:class:`trackingbox.estimation.Problem`,
its windows and its runs), so identifiability and intervals see exactly the
samples, warm-up and parameters the estimation scores.

Sensitivities are *exact* where the twin provides directional derivatives w.r.t.
its parameters (one run integrating the forward sensitivity equations,
:func:`trackingbox.estimation.simulate_window_sensitivities`), else *central
differences* with a step of :data:`FD_STEP` of each parameter's bound range
(one-sided at a bound), ``2 n`` runs.
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import EstimationError, TrackingError
from ..estimation.objective import jacobian_support
from ..simulation.windows import load_windows, problem_from_spec, simulate_window, simulate_window_sensitivities

log = logging.getLogger(__name__)

#: Step of the central differences, as a fraction of each parameter's bound range.
FD_STEP = 1.0e-3
#: Relative solver tolerance of the central differences' runs. At the estimation's 1e-6 the
#: integrator's own variation between two nearby runs (its steps differ) is ~1e-6 of the outputs,
#: which a step of 1e-3 turns into ~1 % errors of the sensitivities: on the heat-exchanger bench the
#: product kht·A then showed a "null" singular value of 0.7 % of the largest instead of 1e-16 with
#: the exact sensitivities. At 1e-9 it is 1e-5.
FD_TOLERANCE = 1.0e-9

Method = Literal["auto", "exact", "fd"]


@dataclass(frozen=True)
class Evaluation:
    """The twin's outputs at one parameter point, on the window's scored samples.

    Attributes
    ----------
    x
        The parameter values (problem order).
    simulated, measured
        Tag -> values at the scored samples.
    jacobian
        Tag -> ``d simulated / d θ`` at the scored samples, shape ``(samples, n)``
        (None when not asked for).
    index
        Tag -> position of each scored sample on the window's grid (to line the
        tags up in time).
    extra
        Further twin outputs asked for (:meth:`TwinWindow.sensitivities`): variable ->
        ``(values, d values / d θ)`` on the window's grid after its lead-in.
    """

    x: np.ndarray
    simulated: dict[str, np.ndarray]
    measured: dict[str, np.ndarray]
    jacobian: dict[str, np.ndarray] | None
    index: dict[str, np.ndarray]
    extra: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    def residuals(self) -> dict[str, np.ndarray]:
        """Tag -> ``simulated - measured`` at the scored samples."""
        return {tag: self.simulated[tag] - self.measured[tag] for tag in self.simulated}


class TwinWindow:
    """Runs of the twin over one window (the estimation's training window by default).

    Parameters
    ----------
    problem
        The estimation problem (:func:`trackingbox.estimation.problem_from_spec`).
    window
        The window (:func:`trackingbox.estimation.load_windows`).
    method
        ``"exact"`` (refused with the reason when the twin cannot), ``"fd"`` or
        ``"auto"`` (exact where the twin provides directional derivatives, else fd).
    """

    def __init__(self, problem: Any, window: Any, method: Method = "auto") -> None:
        if method not in ("auto", "exact", "fd"):
            raise EstimationError(f"sensitivities: method must be auto, exact or fd, not {method!r}")
        self.problem = problem
        self.window = window
        self.valid = {tag: np.isfinite(window.measured[tag]) for tag in problem.outputs}
        requested = {"auto": "prefer-exact", "exact": "exact", "fd": "fd"}[method]
        self.method, self.reason = jacobian_support(problem, window, requested)
        #: twin runs made (a sensitivity run counts one)
        self.runs = 0

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.problem.names)

    def _pack(self, x: np.ndarray, sim: dict[str, np.ndarray], jac: dict[str, np.ndarray] | None,
              extra: Sequence[str] = ()) -> Evaluation:
        out_sim, out_meas, out_jac, index = {}, {}, {}, {}
        for tag in self.problem.outputs:
            ok = self.valid[tag]
            out_sim[tag] = np.asarray(sim[tag], dtype=float)[ok]
            out_meas[tag] = np.asarray(self.window.measured[tag], dtype=float)[ok]
            index[tag] = np.flatnonzero(ok)
            if jac is not None:
                out_jac[tag] = np.asarray(jac[tag], dtype=float)[ok]
        lead = self.window.lead
        more = {name: (np.asarray(sim[_EXTRA + name], dtype=float)[lead:],
                       np.asarray(jac[_EXTRA + name], dtype=float)[lead:]) for name in extra} if jac is not None else {}
        return Evaluation(np.array(x, dtype=float), out_sim, out_meas, out_jac if jac is not None else None, index,
                          more)

    def outputs(self, x: npt.ArrayLike, tolerance: float = 1e-6) -> Evaluation:
        """One run at *x*: the simulated outputs (no sensitivities), at the solver's relative *tolerance*."""
        x = np.asarray(x, dtype=float)
        self.runs += 1
        return self._pack(x, simulate_window(self.problem, self.window, x, tolerance), None)

    def sensitivities(self, x: npt.ArrayLike, extra: Sequence[str] = ()) -> Evaluation:
        """Outputs and their sensitivities at *x* (exact or central differences, see the module).

        *extra*: further twin variables whose values and sensitivities come back in
        :attr:`Evaluation.extra` (on the window's grid after its lead-in).
        """
        x = np.asarray(x, dtype=float)
        problem = self.problem
        if extra:
            problem = replace(problem, outputs={**problem.outputs, **{_EXTRA + n: n for n in extra}})
        if self.method == "exact":
            self.runs += 1
            values, slopes = simulate_window_sensitivities(problem, self.window, x)
            return self._pack(x, values, slopes, extra)
        lo, hi = problem.lower, problem.upper
        values = simulate_window(problem, self.window, x, FD_TOLERANCE)
        self.runs += 1
        columns: dict[str, list[np.ndarray]] = {tag: [] for tag in problem.outputs}
        for j in range(len(x)):
            h = FD_STEP * (hi[j] - lo[j])
            up, down = x.copy(), x.copy()
            up[j] = min(hi[j], x[j] + h)
            down[j] = max(lo[j], x[j] - h)
            y_up = values if up[j] == x[j] else simulate_window(problem, self.window, up, FD_TOLERANCE)
            y_down = values if down[j] == x[j] else simulate_window(problem, self.window, down, FD_TOLERANCE)
            self.runs += int(up[j] != x[j]) + int(down[j] != x[j])
            for tag in problem.outputs:
                columns[tag].append((np.asarray(y_up[tag]) - np.asarray(y_down[tag])) / (up[j] - down[j]))
        return self._pack(x, values, {tag: np.stack(cols, axis=1) for tag, cols in columns.items()}, extra)


#: Prefix of the keys further outputs are simulated under (no tag starts with it).
_EXTRA = "\x00"


def inside_points(start: npt.ArrayLike, lower: npt.ArrayLike, upper: npt.ArrayLike, count: int) -> np.ndarray:
    """*count* points spread inside the bounds (a Halton sequence on the middle 80 % of each range).

    Deterministic; with log-positive bounds the points are spread in ``ln θ``.

    >>> inside_points([1.0, 1.0], [0.5, -1.0], [2.0, 3.0], 2).round(3).tolist()
    [[1.0, 0.467], [0.758, 1.533]]
    """
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    n = lo.size
    primes = _primes(n)
    pts = np.empty((count, n))
    for i in range(count):
        for j in range(n):
            q = 0.1 + 0.8 * _halton(i + 1, primes[j])
            if lo[j] > 0:
                pts[i, j] = float(np.exp(np.log(lo[j]) + q * (np.log(hi[j]) - np.log(lo[j]))))
            else:
                pts[i, j] = lo[j] + q * (hi[j] - lo[j])
    return pts


def _halton(index: int, base: int) -> float:
    f, r = 1.0, 0.0
    while index > 0:
        f /= base
        r += f * (index % base)
        index //= base
    return r


def _primes(count: int) -> list[int]:
    out: list[int] = []
    k = 2
    while len(out) < count:
        if all(k % p for p in out):
            out.append(k)
        k += 1
    return out


def window_for(spec: Any, *, warmup: float | None = None, window: str = "training") -> tuple[Any, Any]:
    """The estimation problem of *spec* and one of its windows (``"training"`` or ``"validation"``)."""
    problem = problem_from_spec(spec, warmup=warmup)
    training, validation = load_windows(spec, warmup=problem.warmup)
    return problem, (training if window == "training" else validation)


def safe(call: Any, what: str) -> Any:
    """Run *call*; a failed twin run becomes an :class:`EstimationError` naming *what* was being done."""
    try:
        return call()
    except TrackingError as exc:
        raise EstimationError(f"{what}: the twin failed ({exc})") from exc


def stack(evaluation: Evaluation, weights: dict[str, float] | None = None,
          factors: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Residuals, Jacobian rows and grid index of all tags, one after another.

    With *weights* (tag -> w) the rows are multiplied by ``sqrt(w)``; with *factors*
    the Jacobian's columns by them (the scaled coordinates).
    """
    rs, js, ix = [], [], []
    res = evaluation.residuals()
    for tag in evaluation.simulated:
        s = np.sqrt(weights[tag]) if weights else 1.0
        rs.append(res[tag] * s)
        if evaluation.jacobian is not None:
            J = evaluation.jacobian[tag] * s
            js.append(J * np.asarray(factors, dtype=float)[None, :] if factors is not None else J)
        ix.append(evaluation.index[tag])
    r = np.concatenate(rs) if rs else np.zeros(0)
    J = np.concatenate(js, axis=0) if js else np.zeros((r.size, 0))
    return r, J, np.concatenate(ix) if ix else np.zeros(0, dtype=int)
