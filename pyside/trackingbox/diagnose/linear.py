"""Linear least squares of the diagnosis: residuals fitted by sensitivity columns, on both windows.

:func:`joint_lstsq` is the noise-weighted (bounded) fit every stage uses; :func:`fit_windows`
fits on training and applies the result on validation, with the ``[diagnose] varying``
candidates' trajectories (:mod:`trackingbox.diagnose.varying`) as extra columns.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.optimize import lsq_linear

from .varying import VaryingBasis


#: Largest condition number of the column-scaled normal matrix ``G = A'A`` that :func:`joint_lstsq` solves
#: by its Cholesky factor (1e5 on the samples' matrix ``A``: the solution's relative error stays near
#: 1e10 * 2e-16 = 2e-6 of what an orthogonal factorisation gives); beyond it, or singular, it factorises the
#: stacked samples (``numpy.linalg.lstsq``, the minimum-norm solution of a rank-deficient fit).
NORMAL_COND = 1e10


def joint_lstsq(residual: Mapping[str, np.ndarray], columns: Mapping[str, np.ndarray],
                noise: Mapping[str, float], bounds: tuple[npt.ArrayLike, npt.ArrayLike] | None = None) -> np.ndarray:
    """Coefficients ``c`` minimising ``sum_tag sum_k ((r - A c) / sigma_tag)**2`` over valid samples.

    *columns*: tag -> ``(n, m)`` matrix ``A`` of that tag (same ``m`` for all tags).
    *bounds*: ``(lower, upper)``, each of length ``m`` (``-inf``/``inf`` where free): the
    bounded least-squares solution where the free one leaves them (the free one otherwise).

    Solved from the normal equations with unit-norm columns where they are well conditioned
    (:data:`NORMAL_COND`): the diagnosis fits a few columns to 10^5 samples thousands of
    times (every candidate's levelling, with the ``[diagnose] varying`` trajectories as 8-14
    extra columns), and on 13 tags x 4320 samples x 14 columns an SVD of the samples took
    107 ms where the normal equations took 8 ms. The bounded solution is that of the
    equivalent ``m``-row system ``L' c ~ L^-1 A'r`` (``A'A = L L'``).

    >>> A = {"y": np.array([[1.0], [2.0], [3.0]])}
    >>> joint_lstsq({"y": np.array([2.0, 4.0, np.nan])}, A, {"y": 1.0}).round(12).tolist()
    [2.0]
    >>> joint_lstsq({"y": np.array([2.0, 4.0, np.nan])}, A, {"y": 1.0}, bounds=([-1.0], [1.5])).round(9).tolist()
    [1.5]
    """
    rows, rhs = [], []
    for tag, r in residual.items():
        r = np.asarray(r, dtype=float)
        a = np.asarray(columns[tag], dtype=float)
        ok = np.isfinite(r) & np.all(np.isfinite(a), axis=1)
        w = 1.0 / noise[tag] if noise[tag] > 0 else 1.0
        rows.append(a[ok] * w)
        rhs.append(r[ok] * w)
    a_all = np.vstack(rows)
    if a_all.shape[1] == 0:
        return np.zeros(0)
    b_all = np.concatenate(rhs)
    lo = hi = None
    if bounds is not None:
        lo = np.asarray(bounds[0], dtype=float)
        hi = np.asarray(bounds[1], dtype=float)
    d = np.sqrt(np.einsum("ij,ij->j", a_all, a_all))
    if np.all(d > 0) and np.all(np.isfinite(d)):
        scaled = a_all / d
        gram = scaled.T @ scaled
        if np.linalg.cond(gram) <= NORMAL_COND:
            chol = cho_factor(gram, lower=True)
            g = scaled.T @ b_all
            coef = cho_solve(chol, g) / d
            if lo is not None and hi is not None and (np.any(coef < lo) or np.any(coef > hi)):
                low = np.tril(chol[0])
                small = lsq_linear(low.T, solve_triangular(low, g, lower=True), bounds=(lo * d, hi * d),
                                   method="bvls")
                coef = small.x / d
            return coef
    coef, *_ = np.linalg.lstsq(a_all, b_all, rcond=None)
    if lo is not None and hi is not None and (np.any(coef < lo) or np.any(coef > hi)):
        coef = lsq_linear(a_all, b_all, bounds=(lo, hi), method="bvls").x
    return coef


def step_bounds(problem: Any, x: npt.ArrayLike, extra: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of a linearised step of the spec's candidates from *x* (the step keeps them inside
    their bounds), followed by *extra* free coefficients.

    >>> from types import SimpleNamespace
    >>> lo, hi = step_bounds(SimpleNamespace(lower=[0.0, 1.0], upper=[2.0, 3.0]), [0.5, 3.0], extra=1)
    >>> lo.tolist(), hi.tolist()
    ([-0.5, -2.0, -inf], [1.5, 0.0, inf])
    """
    x = np.asarray(x, dtype=float)
    lo = np.concatenate([np.asarray(problem.lower, dtype=float) - x, np.full(extra, -np.inf)])
    hi = np.concatenate([np.asarray(problem.upper, dtype=float) - x, np.full(extra, np.inf)])
    return lo, hi


@dataclass(frozen=True)
class WindowFit:
    """A linear fit of residuals on both windows (:func:`fit_windows`).

    Attributes
    ----------
    delta
        The step of the spec's candidates (fitted on training).
    beta
        The coefficients of the extra columns (an effect's terms; fitted on training).
    after_train, after_valid
        Tag -> residual after the fit on each window.
    cost
        Noise-weighted sum of squares on training after the fit.
    varying_train, varying_valid
        Coefficients of the varying candidates' columns on each window (:mod:`.varying`).
    """

    delta: np.ndarray
    beta: np.ndarray
    after_train: dict[str, np.ndarray]
    after_valid: dict[str, np.ndarray]
    cost: float
    varying_train: np.ndarray
    varying_valid: np.ndarray


def fit_windows(r_train: Mapping[str, np.ndarray], r_val: Mapping[str, np.ndarray] | None,
                jac: tuple[Mapping[str, np.ndarray], Mapping[str, np.ndarray]], noise: Mapping[str, float], *,
                bounds: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
                extra_train: Mapping[str, np.ndarray] | None = None, extra_val: Mapping[str, np.ndarray] | None = None,
                varying: VaryingBasis | None = None, x: npt.ArrayLike | None = None) -> WindowFit:
    """Fit ``J delta + T beta (+ V u)`` to the training residuals, noise-weighted; apply it to validation.

    ``J``: the candidates' output sensitivity (*jac*, per window), ``T``: the extra columns
    (tag -> ``(n, m)``; tags without are zero), ``V``: the varying candidates' increments
    (:class:`trackingbox.diagnose.varying.VaryingBasis`). *bounds*: of ``(delta, beta)``
    (:func:`step_bounds`). On validation ``J delta + T beta`` is subtracted with the
    training's coefficients, then the varying candidates' level and increments are fitted
    there (the twin tracks them on any window); *x*: the candidates' values (for the
    validation level's bounds). *r_val* None: the training window alone (``after_valid`` empty).
    """
    j_train, j_val = jac
    tags = list(r_train)
    p = next(iter(j_train.values())).shape[1] if j_train else 0
    m = next(iter(extra_train.values())).shape[1] if extra_train else 0
    n_t = {t: len(r_train[t]) for t in tags}
    n_v = {t: len(r_val[t]) for t in tags} if r_val is not None else {}

    def cols(j: Mapping[str, np.ndarray], extra: Mapping[str, np.ndarray] | None, tag: str, n: int) -> np.ndarray:
        a = j[tag] if tag in j else np.zeros((n, p))
        e = extra[tag] if extra and tag in extra else np.zeros((n, m))
        return np.hstack([a, e])

    ct = {t: cols(j_train, extra_train, t, n_t[t]) for t in tags}
    q = varying.size if varying is not None else 0
    if q:
        vt = varying.columns(j_train, "train", tags, n_t)
        ct = {t: np.hstack([ct[t], vt[t]]) for t in tags}
        if bounds is None:
            bounds = (np.full(p + m, -np.inf), np.full(p + m, np.inf))
        vlo, vhi = varying.bounds("train")
        bounds = (np.concatenate([np.asarray(bounds[0], dtype=float), vlo]),
                  np.concatenate([np.asarray(bounds[1], dtype=float), vhi]))
    coef = joint_lstsq(r_train, ct, noise, bounds)
    if coef.size == 0:
        coef = np.zeros(p + m + q)
    after_t = {t: np.asarray(r_train[t]) - ct[t] @ coef for t in tags}
    u_valid = np.zeros(0)
    if r_val is None:  # the training window alone (its cost and residuals; nothing on validation)
        after_v: dict[str, np.ndarray] = {}
        q_valid = 0
    else:
        after_v = {t: np.asarray(r_val[t]) - cols(j_val, extra_val, t, n_v[t]) @ coef[:p + m] for t in tags}
        q_valid = q
    if q_valid:
        vv = varying.columns(j_val, "valid", tags, n_v)
        x_val = None if x is None else np.asarray(x, dtype=float) + coef[:p]
        u_valid = joint_lstsq(after_v, vv, noise, varying.bounds("valid", x_val))
        if u_valid.size:
            after_v = {t: after_v[t] - vv[t] @ u_valid for t in tags}
    cost = float(sum(np.nansum((after_t[t] / noise[t]) ** 2) for t in tags))
    return WindowFit(coef[:p], coef[p:p + m], after_t, after_v, cost, coef[p + m:], u_valid)
