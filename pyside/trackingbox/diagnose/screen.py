"""Screen every candidate effect cheaply and rank them by the BIC gain on training.

A candidate is an effect entry of the library applied to one target
(:func:`trackingbox.diagnose.library.targets`). How it is screened follows the
entry's ``screen``:

``bias`` / ``drift`` / ``lag``
    A sensor effect only transforms the simulated output of its tag: the null
    model's output is transformed and the transform fitted in closed form or by
    a one-parameter bounded fit: a constant (``bias``), an offset plus a slope in
    time (``drift``; a slope from zero at the first sample for a one-parameter
    entry), a first-order lag of time constant ``tau`` (``lag``, the
    exact discretisation for an output linear between samples).
``coefficient-ramp``
    A parameter of the target (``<target>.<coefficient>``) falls linearly with
    time around the null model's value: ``p(t) = p0 * (1 - rate * (t - t_mid))``
    with ``t_mid`` the middle of the training window, set between steps of the
    twin (:meth:`trackingbox.fmu.FMUModel.stepper`); ``rate`` is a bounded scalar
    fit. No compile.
``levelling-drift`` / ``levelling-ramp``
    The two-parameter forms that grow from the first sample and level off,
    ``d t / (1 + c t)`` added to a tag, and ``p(t) = p0 (1 - r t / (1 + c t))``
    (:func:`levelling`; ``c = 0`` the straight line): ``c`` searched
    (:func:`search_levelling`) with the rate linear at fixed ``c``; the ramp's
    rate is then refined through the twin (:func:`screen_levelling_ramp`).
The spec's candidates are refitted jointly with every screened effect, linearised:
the null model's output sensitivity ``J`` to the candidates (forward differences,
computed once) enters each transform's least squares as extra columns (the lag
filters them too; the ramp fits them at each trial rate), so a bias is not
taken for a shifted coefficient or the reverse (:func:`joint`).

``compile``
    Fitted through its patched, compiled twin with a short budget
    (:func:`trackingbox.diagnose.fit.fit_candidate`) when the settings allow it,
    else skipped with the reason.

Score
-----
For each affected tag ``t`` with ``n_t`` scored samples and residual sums of
squares ``RSS0`` (null) and ``RSS1`` (candidate),

``delta_bic = sum_t n_eff_t * ln(RSS0_t / RSS1_t) - k * ln(N)``

with ``k`` the effect's number of parameters, ``N = sum n_t`` and
``n_eff_t = n_t * (1 - rho) / (1 + rho)`` where ``rho`` (clipped to [0, 0.99])
is the lag-one autocorrelation of the candidate's residual: a candidate that
leaves a coloured residual behind is credited with fewer independent samples.
Positive ``delta_bic`` favours the candidate.
"""
from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar

from ..errors import SpecError, TrackingError
from ..fmu import read_info
from ..simulation.models import cached_model, close_models
from ..simulation.windows import run_start, window_setup
from . import library
from .candidates import Candidate, joint, score
from .fit import screen_compiled
from .parallel import submit
from .residuals import (
    relinearised,
    window_series,
)

if TYPE_CHECKING:
    from .residuals import WhereResult

log = logging.getLogger(__name__)

#: Upper bound of the first-order sensor lag searched when the entry gives none (s).
DEFAULT_MAX_LAG = 1800.0


# --------------------------------------------------------------------------- transforms


def fit_bias(residual: npt.ArrayLike) -> tuple[float, np.ndarray]:
    """Constant ``b`` minimising ``sum (r - b)**2`` (the mean), and the residual after.

    >>> b, after = fit_bias([1.0, 3.0, np.nan])
    >>> b, after.tolist()[:2]
    (2.0, [-1.0, 1.0])
    """
    r = np.asarray(residual, dtype=float)
    b = float(np.nanmean(r))
    return b, r - b


def fit_drift(time: npt.ArrayLike, residual: npt.ArrayLike) -> tuple[tuple[float, float], np.ndarray]:
    """Offset ``a`` (at the first sample) and slope ``c`` (per second) of ``r ~ a + c (t - t0)``.

    >>> (a, c), after = fit_drift([0.0, 10.0, 20.0], [1.0, 1.5, 2.0])
    >>> round(a, 6), round(c, 6), float(np.abs(after).max()) < 1e-12
    (1.0, 0.05, True)
    """
    t = np.asarray(time, dtype=float)
    r = np.asarray(residual, dtype=float)
    ok = np.isfinite(r)
    dt = t - t[0]
    a_mat = np.column_stack([np.ones(ok.sum()), dt[ok]])
    coef, *_ = np.linalg.lstsq(a_mat, r[ok], rcond=None)
    return (float(coef[0]), float(coef[1])), r - (coef[0] + coef[1] * dt)


def first_order(time: npt.ArrayLike, y: npt.ArrayLike, tau: float) -> np.ndarray:
    """Output of ``tau dx/dt = y - x``, ``x(t0) = y(t0)``, for *y* linear between samples.

    Exact for a piecewise-linear input: with ``h`` the step and ``a = exp(-h / tau)``,
    ``x_{k+1} = a x_k + (1 - a) y_{k+1} - (tau (1 - a) - a h) (y_{k+1} - y_k) / h``.

    A ramp of slope 1 is followed with the delay ``tau`` once the transient has died out:

    >>> t = np.arange(0.0, 200.0, 5.0)
    >>> x = first_order(t, t, 10.0)
    >>> round(float(t[-1] - x[-1]), 6)
    10.0
    """
    t = np.asarray(time, dtype=float)
    u = np.asarray(y, dtype=float)
    if tau <= 0:
        return u.copy()
    steps = np.diff(t)
    if steps.size and np.allclose(steps, steps[0], rtol=1e-9, atol=0.0):
        # uniform grid: the recurrence is a linear filter on u - u0 with a zero initial state
        # deferred (start-up): scipy.signal adds 0.45-0.54 s to an import of the package (python -X importtime,
        # on top of numpy/pandas/scipy.optimize) for one filter call
        from scipy.signal import lfilter

        h = float(steps[0])
        a = math.exp(-h / tau)
        b0 = 1.0 - tau / h + tau * a / h
        b1 = tau / h - a - tau * a / h
        return u[0] + lfilter([b0, b1], [1.0, -a], u - u[0])
    x = np.empty_like(u)
    x[0] = u[0]
    for k in range(len(u) - 1):
        h = t[k + 1] - t[k]
        a = math.exp(-h / tau)
        slope = (u[k + 1] - u[k]) / h
        # x(h) = u_{k+1} - tau*slope + (x_k - u_k + tau*slope) * a
        x[k + 1] = u[k + 1] - tau * slope + (x[k] - u[k] + tau * slope) * a
    return x


def fit_lag(time: npt.ArrayLike, simulated: npt.ArrayLike, measured: npt.ArrayLike, *,
            bounds: tuple[float, float] = (0.0, DEFAULT_MAX_LAG)) -> tuple[float, np.ndarray]:
    """Time constant ``tau`` in *bounds* whose first-order lag of *simulated* best fits *measured*.

    Returns ``tau`` and the residual ``measured - lag(simulated)``.
    """
    t = np.asarray(time, dtype=float)
    y = np.asarray(simulated, dtype=float)
    m = np.asarray(measured, dtype=float)
    ok = np.isfinite(m)

    def sse(tau: float) -> float:
        e = m[ok] - first_order(t, y, tau)[ok]
        return float(np.dot(e, e))

    lo, hi = max(0.0, float(bounds[0])), float(bounds[1])
    res = minimize_scalar(sse, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3 * (hi - lo) + 1e-6})
    tau = float(res.x)
    if sse(lo) <= res.fun:
        tau = lo
    return tau, m - first_order(t, y, tau)


def levelling(time: npt.ArrayLike, c: float) -> np.ndarray:
    """Shape of an error that grows from the first sample and levels off: ``t / (1 + c t)``, 0 before ``t = 0``.

    Its slope at ``t = 0`` is 1; it reaches half its limit ``1 / c`` at ``t = 1 / c``;
    ``c = 0`` is the straight line ``t`` (the nested linear form).

    >>> levelling([-5.0, 0.0, 10.0, 100.0], 0.01).tolist()
    [0.0, 0.0, 9.09090909090909, 50.0]
    >>> levelling([10.0], 0.0).tolist()
    [10.0]
    """
    t = np.maximum(np.asarray(time, dtype=float), 0.0)
    return t / (1.0 + c * t)


#: Points of the first search over the levelling coefficient ``c`` (besides ``c = 0``): log-spaced over its range.
LEVELLING_GRID = 24


def search_levelling(cost: Callable[[float], float], upper: float, *, lower: float = 0.0) -> float:
    """The levelling coefficient ``c`` in ``[lower, upper]`` that minimises *cost*.

    *cost* is cheap (a linear fit at fixed ``c``): a grid of ``c = lower`` and
    :data:`LEVELLING_GRID` log-spaced values up to *upper*, then a bounded scalar
    search between the best point's neighbours.

    >>> round(search_levelling(lambda c: (c - 3e-4) ** 2, 1e-3) / 3e-4, 4)
    1.0
    >>> search_levelling(lambda c: c, 1e-3)
    0.0
    """
    lo_pos = max(lower, upper * 1e-4)
    grid = np.concatenate(([lower], np.geomspace(lo_pos, upper, LEVELLING_GRID)))
    costs = np.array([cost(float(c)) for c in grid])
    i = int(np.nanargmin(costs))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    best, best_cost = float(grid[i]), float(costs[i])
    if b > a:
        res = minimize_scalar(cost, bounds=(float(a), float(b)), method="bounded",
                              options={"xatol": 1e-3 * float(b - a)})
        if res.fun < best_cost:
            best = float(res.x)
    return best


def _bounds_of(effect: Any, index: int, default: tuple[float, float]) -> tuple[float, float]:
    """(min, max) of the entry's parameter number *index* (*default* when it has none)."""
    params = list(getattr(effect, "parameters", ()) or ())
    if index < len(params):
        p = params[index]
        return float(getattr(p, "min", default[0])), float(getattr(p, "max", default[1]))
    return default


def _bounds(effect: Any, default: tuple[float, float]) -> tuple[float, float]:
    params = list(getattr(effect, "parameters", ()) or ())
    if len(params) == 1:
        p = params[0]
        return float(getattr(p, "min", default[0])), float(getattr(p, "max", default[1]))
    return default


def sensor_fit(effect: Any, tag: str, base: WhereResult) -> tuple[dict[str, float], dict[str, np.ndarray],
                                                                   dict[str, np.ndarray], np.ndarray]:
    """Fit a sensor transform on *tag* jointly with the candidates, linearised around *base*.

    Returns the effect's values, the residuals after on training and validation, and the candidates' step.
    """
    how = effect.screen
    k = len(getattr(effect, "parameters", ()) or ()) or 1
    tr, va = base.training, base.validation
    rt = {t: tr.residual(t) for t in base.tags}
    rv = {t: va.residual(t) for t in base.tags}
    if how == "bias":
        beta, after_t, after_v, _, delta = joint(base, rt, rv, {tag: np.ones((tr.time.size, 1))},
                                                 {tag: np.ones((va.time.size, 1))})
        return {"bias": float(beta[0])}, after_t, after_v, delta
    if how == "drift" and k == 1:
        # one parameter: the error grows from zero at the first sample (grid time 0)
        beta, after_t, after_v, _, delta = joint(base, rt, rv, {tag: tr.time[:, None]}, {tag: va.time[:, None]})
        return {"rate": float(beta[0])}, after_t, after_v, delta
    if how == "drift":
        t0 = tr.time[0]
        beta, after_t, after_v, _, delta = joint(
            base, rt, rv, {tag: np.column_stack([np.ones(tr.time.size), tr.time - t0])},
            {tag: np.column_stack([np.ones(va.time.size), va.time - t0])})
        return {"offset": float(beta[0]), "rate": float(beta[1])}, after_t, after_v, delta
    if how == "levelling-drift":
        # error d * t / (1 + c t) from the first sample: linear in d at fixed c, c searched
        c_hi = _bounds_of(effect, 1, (0.0, 1.0e-3))[1]

        def fit_at(c: float) -> tuple[Any, ...]:
            return joint(base, rt, rv, {tag: levelling(tr.time, c)[:, None]}, {tag: levelling(va.time, c)[:, None]})

        c = search_levelling(lambda c: fit_at(c)[3], c_hi)
        beta, after_t, after_v, _, delta = fit_at(c)
        return {"rate": float(beta[0]), "levelling": c}, after_t, after_v, delta
    if how == "lag":
        lo, hi = _bounds(effect, (0.0, DEFAULT_MAX_LAG))
        lo = max(lo, 0.0)
        j_train, j_val = base.jacobian

        def lagged(tau: float) -> tuple[Any, ...]:
            rt2, rv2 = dict(rt), dict(rv)
            rt2[tag] = tr.measured[tag] - first_order(tr.time, tr.simulated[tag], tau)
            rv2[tag] = va.measured[tag] - first_order(va.time, va.simulated[tag], tau)
            jt, jv = dict(j_train), dict(j_val)
            if tag in jt and jt[tag].shape[1]:
                jt[tag] = np.column_stack([first_order(tr.time, c, tau) for c in jt[tag].T])
                jv[tag] = np.column_stack([first_order(va.time, c, tau) for c in jv[tag].T])
            return joint(base, rt2, rv2, jac=(jt, jv))

        res = minimize_scalar(lambda tau: lagged(tau)[3], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-3 * (hi - lo) + 1e-6})
        tau = float(res.x)
        _, after_t, after_v, cost, delta = lagged(tau)
        low = lagged(lo)
        if low[3] <= cost:
            tau = lo
            _, after_t, after_v, _, delta = low
        return {"tau": tau}, after_t, after_v, delta
    raise ValueError(f"not a sensor screen: {how!r}")


#: A joint fit is re-linearised where it moved the candidates by more than this share of their ranges.
RELINEARISE_STEP = 1.0e-3


def screen_sensor(effect: Any, tag: str, where: WhereResult, *, relinearise: bool = True) -> Candidate:
    """Screen a sensor effect on *tag*: transform the null model's output, refit the candidates linearised.

    With *relinearise*, a fit that moved the candidates is repeated once around
    the moved point (one more Gauss-Newton step: ``1 + p`` simulations per window).
    """
    k = len(getattr(effect, "parameters", ()) or ()) or 1
    values, after_t, after_v, delta = sensor_fit(effect, tag, where)
    problem = where.problem
    if (relinearise and problem is not None and where.x is not None and delta.size
            and np.any(np.abs(delta) > RELINEARISE_STEP * (problem.upper - problem.lower))):
        values, after_t, after_v, _ = sensor_fit(effect, tag, relinearised(where, delta))
    pinned = []
    if effect.screen == "lag":
        lo, hi = _bounds(effect, (0.0, DEFAULT_MAX_LAG))
        if values["tau"] >= hi - 1e-3 * (hi - lo):
            pinned.append("tau")
    params = list(getattr(effect, "parameters", ()) or ())
    if len(params) == 1 and len(values) == 1:
        # a one-parameter entry: report the screened quantity under the entry's own parameter name
        values = {params[0].name: next(iter(values.values()))}
        pinned = [params[0].name] if pinned else []
    elif effect.screen == "levelling-drift" and len(params) == 2:
        # (rate, levelling) under the entry's own names; c at its upper bound: a step, not a drift
        values = {params[0].name: values["rate"], params[1].name: values["levelling"]}
        c_lo, c_hi = _bounds_of(effect, 1, (0.0, 1.0e-3))
        if values[params[1].name] >= c_hi - 1e-3 * (c_hi - c_lo):
            pinned.append(params[1].name)
    return score(effect.id, tag, "sensor", "screen", where, k, after_t, after_v, values, pinned=pinned)


def simulate_ramp(where: WhereResult, window: Any, x: npt.ArrayLike, name: str, base: float, rate: float,
                  t_mid: float, *, interval: float = 300.0,
                  schedule: Callable[[float], float] | None = None) -> dict[str, np.ndarray]:
    """Simulate *window* with parameter *name* = ``base * (1 - rate * (t - t_mid))``, set between steps.

    Times are seconds from the first sample; *rate* is per second; *schedule*
    (time -> value), when given, replaces that straight line. The run
    starts as :func:`trackingbox.estimation.simulate_window`'s (its warm-up through
    the measured history, the spec's input rule and initial state), with the
    parameter at its value at the window's first grid point.
    Returns output tag -> values on the window's grid (lead-in cut off).
    """
    problem = where.problem
    parameters, offset, grid, inputs = window_setup(problem, window, x)
    t0 = run_start(problem, window)

    def value_at(t_abs: float) -> float:
        if schedule is not None:
            return float(schedule(t_abs))
        return base * (1.0 - rate * (t_abs - t_mid))

    parameters[name] = value_at(float(window.time[0]))
    model = cached_model(problem.twin)
    stepper = model.stepper(start_time=t0, parameters=parameters, inputs=inputs, input_rule=problem.inputs)
    if problem.initial == "steady":
        stepper.settle()
    outputs = list(problem.outputs.values())
    if offset > 0:
        stepper.step(t0 + offset)
    result = np.empty((grid.size, len(outputs)))
    result[0] = stepper.get(outputs)
    every = max(1, int(round(interval / problem.sample_time)))
    for i in range(1, grid.size):
        if (i - 1) % every == 0:
            stepper.set({name: value_at(float(window.time[i - 1]) + 0.5 * every * problem.sample_time)})
        stepper.step(t0 + offset + float(grid[i]))
        result[i] = stepper.get(outputs)
    keep = slice(window.lead, None)
    return {tag: result[keep, j] for j, tag in enumerate(problem.outputs)}


def read_info_start(fmu: Any, name: str) -> float | None:
    """Start value of variable *name* in *fmu* (None if absent or without a start)."""
    for v in read_info(fmu).variables:
        if v.name == name and v.start is not None:
            try:
                return float(v.start)
            except (TypeError, ValueError):
                return None
    return None


def screen_ramp(effect: Any, target: str, where: WhereResult, *, max_fall: float = 0.5,
                evaluations: int = 12) -> Candidate:
    """Screen a coefficient that falls linearly with time (fouling) on *target*, without compiling."""
    problem = where.problem
    name = f"{target}.{effect.coefficient}"
    x = np.array([where.null.parameters.get(n, s) for n, s in zip(problem.names, problem.start)])
    if name in problem.names:
        base = float(x[list(problem.names).index(name)])
    elif name in problem.fixed:
        base = float(problem.fixed[name])
    else:
        base = read_info_start(problem.twin, name)
        if base is None:
            return Candidate(effect.id, target, "process", "skipped",
                             reason=f"the twin has no tunable parameter {name!r} to ramp")
    training, validation = where.windows
    tr = where.training
    t_mid = 0.5 * (float(tr.time[0]) + float(tr.time[-1]))
    span = float(tr.time[-1] - tr.time[0])
    k = len(getattr(effect, "parameters", ()) or ()) or 1
    tags = list(problem.outputs)

    va = where.validation
    rv0 = {t: va.residual(t) for t in tags}

    def fitted(rate: float, sim_v: Mapping[str, np.ndarray] | None = None) -> tuple[Any, ...]:
        sim = simulate_ramp(where, training, x, name, base, rate, t_mid)
        rt = {t: tr.measured[t] - sim[t] for t in tags}
        rv = rv0 if sim_v is None else {t: va.measured[t] - sim_v[t] for t in tags}
        return joint(where, rt, rv)

    def sse(rate: float) -> float:
        try:
            return fitted(rate)[3]
        except Exception as exc:  # noqa: BLE001 - a failing point is a bad point
            log.debug("ramp %g failed: %s", rate, exc)
            return math.inf

    hi = max_fall / max(span, 1.0)
    try:
        res = minimize_scalar(sse, bounds=(0.0, hi), method="bounded",
                              options={"maxiter": evaluations, "xatol": 1e-3 * hi})
        rate = float(res.x)
        sim_v = simulate_ramp(where, validation, x, name, base, rate, t_mid)
        _, after_t, after_v, _, _ = fitted(rate, sim_v)
    finally:
        close_models()
    pinned = ["rate"] if rate >= hi * 0.999 else []
    return score(effect.id, target, "process", "screen", where, k, after_t, after_v,
                 {"rate": rate, name: base}, pinned=pinned)


def coefficient_base(effect: Any, target: str, where: WhereResult) -> tuple[str, float | None]:
    """``<target>.<coefficient>`` and its null-model value (fitted candidate, fixed value or the FMU's start)."""
    problem = where.problem
    name = f"{target}.{effect.coefficient}"
    if name in problem.names:
        x = where.x if where.x is not None else problem.start
        return name, float(x[list(problem.names).index(name)])
    if name in problem.fixed:
        return name, float(problem.fixed[name])
    return name, read_info_start(problem.twin, name)


def coefficient_sensitivity(where: WhereResult, name: str, base: float) -> tuple[dict[str, np.ndarray], ...]:
    """Per window, tag -> sensitivity of the simulated output to a constant change of *name* (per unit).

    The null model's Jacobian column where *name* is a candidate, else one forward
    difference (a step of 1e-3 of *base*) per window.
    """
    problem = where.problem
    j_train, j_val = where.jacobian
    if name in problem.names and j_train:
        i = list(problem.names).index(name)
        return {t: j[:, i] for t, j in j_train.items()}, {t: j[:, i] for t, j in j_val.items()}
    h = 1e-3 * (abs(base) or 1.0)
    moved = dataclasses.replace(problem, fixed={**problem.fixed, name: base + h})
    x = where.x if where.x is not None else problem.start
    out = []
    try:
        for window in where.windows:
            after = window_series(moved, window, x, where.input_tags)
            plain = window_series(problem, window, x, where.input_tags)
            out.append({t: (after.simulated[t] - plain.simulated[t]) / h for t in problem.outputs})
    finally:
        close_models()
    return out[0], out[1]


def screen_levelling_ramp(effect: Any, target: str, where: WhereResult, *, evaluations: int = 8) -> Candidate:
    """Screen a coefficient that falls from the first sample and levels off (fouling) on *target*, no compile.

    ``p(t) = p0 * (1 - r * t / (1 + c t))`` (:func:`levelling`; ``c = 0`` the straight
    line): the levelling ``c`` and a first ``r`` from the quasi-static linearisation
    (the output moves by ``S(t) * dp(t)``, ``S`` the sensitivity to a constant change,
    :func:`coefficient_sensitivity`; the coefficient changes over hours, the twin
    settles in minutes), jointly with the candidates; then ``r`` at that ``c`` by a
    bounded scalar fit through the twin with ``p(t)`` set between steps
    (:func:`simulate_ramp`), as the linear ramp is.
    """
    problem = where.problem
    name, base = coefficient_base(effect, target, where)
    if base is None:
        return Candidate(effect.id, target, "process", "skipped",
                         reason=f"the twin has no tunable parameter {name!r} to ramp")
    params = list(getattr(effect, "parameters", ()) or ())
    r_lo, r_hi = _bounds_of(effect, 0, (0.0, 1.0e-5))
    c_lo, c_hi = _bounds_of(effect, 1, (0.0, 1.0e-3))
    tr, va = where.training, where.validation
    tags = list(problem.outputs)
    s_t, s_v = coefficient_sensitivity(where, name, base)
    rt0 = {t: tr.residual(t) for t in tags}
    rv0 = {t: va.residual(t) for t in tags}

    def linear_at(c: float) -> tuple[Any, ...]:
        gt, gv = levelling(tr.time, c), levelling(va.time, c)
        return joint(where, rt0, rv0, {t: (-base * s_t[t] * gt)[:, None] for t in tags},
                     {t: (-base * s_v[t] * gv)[:, None] for t in tags})

    c = search_levelling(lambda c: linear_at(c)[3], c_hi, lower=max(c_lo, 0.0))
    r_lin = float(min(max(linear_at(c)[0][0], r_lo), r_hi))
    training, validation = where.windows
    x = where.x if where.x is not None else problem.start

    def schedule(r: float) -> Callable[[float], float]:
        return lambda t: base * max(1.0 - r * float(levelling([t], c)[0]), 0.05)

    def fitted(r: float, sim_v: Mapping[str, np.ndarray] | None = None) -> tuple[Any, ...]:
        sim = simulate_ramp(where, training, x, name, base, 0.0, 0.0, schedule=schedule(r))
        rt = {t: tr.measured[t] - sim[t] for t in tags}
        rv = rv0 if sim_v is None else {t: va.measured[t] - sim_v[t] for t in tags}
        return joint(where, rt, rv)

    def sse(r: float) -> float:
        try:
            return fitted(r)[3]
        except Exception as exc:  # noqa: BLE001 - a failing point is a bad point
            log.debug("levelling ramp %g failed: %s", r, exc)
            return math.inf

    try:
        r = r_lin
        if r_lin > r_lo:
            lo, hi = max(r_lo, 0.5 * r_lin), min(r_hi, 1.5 * r_lin)
            res = minimize_scalar(sse, bounds=(lo, hi), method="bounded",
                                  options={"maxiter": evaluations, "xatol": 1e-3 * (hi - lo)})
            if res.fun < sse(r_lin):
                r = float(res.x)
        sim_v = simulate_ramp(where, validation, x, name, base, 0.0, 0.0, schedule=schedule(r))
        _, after_t, after_v, _, _ = fitted(r, sim_v)
    finally:
        close_models()
    k = len(params) or 2
    pinned = []
    if r >= r_hi - 1e-3 * (r_hi - r_lo):
        pinned.append(params[0].name if params else "r")
    if c >= c_hi - 1e-3 * (c_hi - c_lo):
        pinned.append(params[1].name if len(params) > 1 else "c")
    values = {(params[0].name if params else "r"): r, (params[1].name if len(params) > 1 else "c"): c, name: base}
    return score(effect.id, target, "process", "screen", where, k, after_t, after_v, values, pinned=pinned)


def screen(effects: Mapping[str, Any], spec: Any, where: WhereResult, *,
           fit_compiled: Callable[[Any, str], Candidate] | None = None,
           only: Sequence[str] = (), progress: Callable[[str, int, int], None] | None = None,
           relinearise: int = 3, compiled_in: Any = None, exclude: Collection[str] = ()) -> list[Candidate]:
    """Screen every effect × target; return the candidates ranked by ``delta_bic`` (best first).

    Parameters
    ----------
    effects
        Effect id -> entry (:func:`trackingbox.diagnose.library.load_effects`).
    spec
        The loaded spec (targets are found in it).
    where
        The null model's residuals (:func:`trackingbox.diagnose.residuals.where`).
    fit_compiled
        ``fit_compiled(effect, target) -> Candidate`` for ``screen = "compile"``
        entries (a short fit of the patched twin); None: those are skipped.
    only
        Effect ids to screen (all when empty).
    progress
        ``progress("screen", done, total)``.
    relinearise
        How many of the best sensor candidates are fitted again around their moved candidates
        (:func:`screen_sensor`).
    compiled_in
        Work folder (path) for ``compile`` entries screened by
        :func:`trackingbox.diagnose.fit.screen_compiled` as jobs of their own (on the workers of an
        active :func:`trackingbox.diagnose.parallel.pool`); when given, *fit_compiled* is not used.
    exclude
        ``"effect@target"`` pairs not screened (``diagnose --apply``: those already in the twin, whose
        second copy would not compile: a heat-loss patch on a twin patched with one declares its
        port's equation twice).
    """
    jobs = []
    out: list[Candidate] = []
    for eid in sorted(effects):
        if only and eid not in only:
            continue
        effect = effects[eid]
        try:
            found = library.targets(effect, spec)
        except SpecError as exc:
            out.append(Candidate(eid, "", getattr(effect, "kind", "process"), "skipped", reason=str(exc)))
            continue
        jobs.extend((effect, target) for target in found if f"{eid}@{target}" not in exclude)
    # the expensive jobs (a ramp's search, a compiled patch) start on the workers of an active
    # parallel.pool first; the cheap sensor transforms run here meanwhile; results keep the jobs' order
    # (the longest first, job_cost: a long job started last would leave the other workers idle at the end;
    # the cheap ones here all run before the first result is waited for)
    heavy = ("coefficient-ramp", "levelling-ramp")
    pending: dict[int, Callable[[], Candidate]] = {}
    for i in sorted(range(len(jobs)), key=lambda i: -job_cost(jobs[i][0])):
        effect, target = jobs[i]
        how = getattr(effect, "screen", "compile")
        if how in heavy or (how not in SENSOR_SCREENS and compiled_in is not None):
            pending[i] = submit(screen_job, (effect, target, spec, where, compiled_in))
    here: dict[int, Candidate] = {}
    for i, (effect, target) in enumerate(jobs):
        if i in pending:
            continue
        if getattr(effect, "screen", "compile") not in SENSOR_SCREENS and fit_compiled is not None:
            here[i] = _guarded(effect, target, lambda e, t: fit_compiled(e, t))
        else:
            here[i] = screen_job(effect, target, spec, where, None)
    for i, (effect, target) in enumerate(jobs):
        cand = here[i] if i in here else pending[i]()
        log.info("screened %s on %s: delta BIC %.4g, validation gain %.3g", cand.effect, cand.target,
                 cand.delta_bic, cand.validation_gain)
        out.append(cand)
        if progress is not None:
            progress("screen", i + 1, len(jobs))
    # the best few sensor candidates once more, re-linearised around where their joint fit moved the candidates
    ranked = rank(out)
    sensors = [c for c in ranked if c.stage == "screen" and c.kind == "sensor" and c.delta_bic > 0][:relinearise]
    for c in sensors:
        again = screen_sensor(effects[c.effect], c.target, where, relinearise=True)
        ranked[ranked.index(c)] = again
    return rank(ranked)


#: Screens that transform the null model's output (cheap; no run of the twin).
SENSOR_SCREENS = ("bias", "drift", "lag", "levelling-drift")


def job_cost(effect: Any) -> float:
    """About how many runs of the twin screening *effect* on one target costs (the order jobs start in).

    A ``compile`` entry: its compile (about two runs) and ``1 + k`` runs per window for ``k``
    parameters, each again at three quartiles of an onset's variable (:func:`trackingbox.diagnose.fit.onset_starts`);
    a ramp: its search's runs; a sensor transform: none.

    >>> from types import SimpleNamespace as NS
    >>> job_cost(NS(screen="compile", parameters=[NS(onset_of="")]))
    6.0
    >>> job_cost(NS(screen="compile", parameters=[NS(onset_of=""), NS(onset_of="x"), NS(onset_of="")]))
    34.0
    >>> job_cost(NS(screen="bias", parameters=[]))
    0.0
    """
    how = getattr(effect, "screen", "compile")
    if how in SENSOR_SCREENS:
        return 0.0
    if how == "coefficient-ramp":
        return 14.0
    if how == "levelling-ramp":
        return 12.0
    params = list(getattr(effect, "parameters", ()) or ())
    onsets = sum(1 for p in params if getattr(p, "onset_of", ""))
    return 2.0 + 2.0 * (1 + (len(params) or 1)) * (1 + 3 * onsets)


def _guarded(effect: Any, target: str, how: Callable[[Any, str], Candidate]) -> Candidate:
    """``how(effect, target)``; a failure of the twin or of the fit leaves a skipped candidate with the reason."""
    try:
        return how(effect, target)
    except Exception as exc:  # noqa: BLE001 - one failing candidate does not stop the screening
        if not isinstance(exc, (TrackingError, ArithmeticError, ValueError)):
            raise
        log.warning("screening %s on %s failed: %s", effect.id, target, exc)
        return Candidate(effect.id, target, getattr(effect, "kind", "process"), "skipped",
                         reason=f"screening failed: {exc}")


def screen_job(effect: Any, target: str, spec: Any, where: WhereResult, compiled_in: Any) -> Candidate:
    """Screen one effect on one target (a job of :func:`screen`; module level, so a worker can run it).

    ``compile`` entries are screened through :func:`trackingbox.diagnose.fit.screen_compiled`
    in the folder *compiled_in*, or skipped with the reason when it is None.
    """
    how = getattr(effect, "screen", "compile")

    def run(effect: Any, target: str) -> Candidate:
        if how in SENSOR_SCREENS:
            if target not in where.tags:
                return Candidate(effect.id, target, "sensor", "skipped",
                                 reason=f"tag {target!r} is not an output tag of the spec")
            return screen_sensor(effect, target, where, relinearise=False)
        if how == "coefficient-ramp":
            return screen_ramp(effect, target, where)
        if how == "levelling-ramp":
            return screen_levelling_ramp(effect, target, where)
        if compiled_in is not None:
            return screen_compiled(spec, where, effect, target, Path(compiled_in))
        return Candidate(effect.id, target, getattr(effect, "kind", "process"), "skipped",
                         reason="screened only by compiling its patch, which these settings do not allow")

    return _guarded(effect, target, run)


def rank(candidates: Sequence[Candidate]) -> list[Candidate]:
    """Best first: by ``delta_bic`` (NaN last), then effect and target for a stable order."""
    return sorted(candidates, key=lambda c: (-(c.delta_bic if math.isfinite(c.delta_bic) else -math.inf),
                                             c.effect, c.target))
