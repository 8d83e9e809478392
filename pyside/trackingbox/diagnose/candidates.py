"""A screened candidate and how it is scored: :class:`Candidate`, :func:`score`, :func:`delta_bic`,
and the joint linearised fit of an effect's terms with the spec's candidates (:func:`joint`).

The common ground of the screening (:mod:`.screen`), the fits of patched twins (:mod:`.fit`) and
the judgement (:mod:`.judge`); it imports none of them.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from .residuals import (
    fit_windows,
    ljung_box_lag1,
    step_bounds,
)

if TYPE_CHECKING:
    from .residuals import WhereResult

log = logging.getLogger(__name__)


def delta_bic(before: Mapping[str, npt.ArrayLike], after: Mapping[str, npt.ArrayLike], k: int) -> float:
    """BIC of the null minus BIC of the candidate (module docstring), over the tags of *after*.

    >>> rng = np.random.default_rng(0)
    >>> e = rng.normal(0.0, 1.0, 1000)
    >>> delta_bic({"y": e + 1.0}, {"y": e}, 1) > 100
    True
    >>> delta_bic({"y": e}, {"y": e - e.mean()}, 1) < 0
    True
    """
    total, n_all = 0.0, 0
    for tag, r1 in after.items():
        r1 = np.asarray(r1, dtype=float)
        r0 = np.asarray(before[tag], dtype=float)
        ok = np.isfinite(r0) & np.isfinite(r1)
        n = int(ok.sum())
        if n < 3:
            continue
        rss0 = float(np.dot(r0[ok], r0[ok]))
        rss1 = float(np.dot(r1[ok], r1[ok]))
        rho = min(max(ljung_box_lag1(r1[ok]), 0.0), 0.99)
        n_eff = n * (1.0 - rho) / (1.0 + rho)
        total += n_eff * math.log(max(rss0, 1e-300) / max(rss1, 1e-300))
        n_all += n
    return total - k * math.log(max(n_all, 1))


def noise_gain(before: npt.ArrayLike, after: npt.ArrayLike, sigma: float) -> float:
    """Drop of the mean square residual, in noise variances: ``(MSE0 - MSE1) / sigma**2``.

    >>> round(noise_gain([2.0, -2.0, 2.0], [1.0, -1.0, 1.0], 1.0), 3)
    3.0
    """
    r0 = np.asarray(before, dtype=float)
    r1 = np.asarray(after, dtype=float)
    ok = np.isfinite(r0) & np.isfinite(r1)
    if not ok.any() or not sigma > 0:
        return math.nan
    return float((np.mean(r0[ok] ** 2) - np.mean(r1[ok] ** 2)) / sigma ** 2)


def nrmse_of(residual: npt.ArrayLike, measured: npt.ArrayLike) -> float:
    """RMS of *residual* over the range of *measured* (valid samples), as estimation's NRMSE."""
    r = np.asarray(residual, dtype=float)
    m = np.asarray(measured, dtype=float)
    ok = np.isfinite(r) & np.isfinite(m)
    if not ok.any():
        return math.nan
    span = float(m[ok].max() - m[ok].min())
    scale = span if span > 0 else max(abs(float(m[ok].mean())), 1.0)
    return float(np.sqrt(np.mean(r[ok] ** 2)) / scale)


# --------------------------------------------------------------------------- bounds


#: Evidence (a likelihood-ratio statistic, :func:`bound_evidence`) beyond which a fitted :func:`zero_able`
#: effect parameter at one of its bounds is *pinned* there by the data: its unbounded estimate lies more
#: than two standard errors beyond the bound. A bound inside the parameter's own noise is no sign of a wrong
#: form: on the evaporator without hidden effect (``bench evaporator --hidden clean``, 24 h, seed 0) the
#: product DS meter's noise alone, 784 exception-reported records over the day, leaves a trend of
#: -4.3e-5 per hour in the null model's QI-6150 residual (its standard error from 385 records on a 12 h
#: window: 4.1e-5 per hour), and the ``ds-meter`` entry's drift bound, 1e-8 1/s = 3.6e-5 per hour, lies
#: within it; the same noise on the ``density-meter`` case held that drift at its bound and refused the
#: right entry.
PIN_EVIDENCE = 4.0


def bound_evidence(at_bound: Mapping[str, npt.ArrayLike], freed: Mapping[str, npt.ArrayLike]) -> float:
    """How strongly the data want a parameter beyond its bound: ``sum_t n_eff_t ln(RSS_bound / RSS_freed)``.

    *at_bound*: residuals with the parameter at its bound; *freed*: with it fitted free of that bound
    (the other terms refitted in both). With Gaussian noise this is the likelihood-ratio statistic of
    the bound, ``((p_free - bound) / se)**2`` for a parameter entering linearly, over the effective
    samples :func:`delta_bic` counts (``delta_bic`` with ``k = 0``).

    >>> t = np.arange(100.0)
    >>> e = np.tile([1.0, -1.0], 50)
    >>> round(bound_evidence({"y": e + 0.01 * (t - t.mean())}, {"y": e}), 1)
    7.1
    """
    return delta_bic(at_bound, freed, 0)


def zero_able(lo: float, hi: float) -> bool:
    """0 lies inside ``(lo, hi)``: the parameter's "no effect" value is inside its range, and the entry with it
    at 0 is its reduced form (a meter's drift, a signed bias or gain). Its bounds then limit a size, not a form.

    >>> zero_able(-1e-8, 1e-8), zero_able(0.0, 1e-3), zero_able(1.0, 900.0)
    (True, False, False)
    """
    return lo < 0.0 < hi


def pinned_at_bounds(values: Mapping[str, float], bounds: Mapping[str, tuple[float, float]],
                     evidence: Mapping[str, float] | None = None) -> list[str]:
    """The effect parameters pinned at a bound: within 0.1 % of its range of the bound, and, for a
    :func:`zero_able` parameter, held there by the data (*evidence*: name -> :func:`bound_evidence`, above
    :data:`PIN_EVIDENCE`; a name without evidence counts as held). A lower bound of 0 is the "no effect"
    value (a leak of 0): a null result, never a pin. A bound of a parameter that cannot be 0 inside its
    range is a limit of the entry's form (a drift's levelling ``c`` at its largest is a step, not a
    drift) and pins it whatever the evidence, as before.

    >>> pinned_at_bounds({"g": 0.05, "d": -1e-8}, {"g": (-0.1, 0.1), "d": (-1e-8, 1e-8)})
    ['d']
    >>> pinned_at_bounds({"g": 0.05, "d": -1e-8}, {"g": (-0.1, 0.1), "d": (-1e-8, 1e-8)}, {"d": 1.2})
    []
    >>> pinned_at_bounds({"c": 1e-3}, {"c": (0.0, 1e-3)}, {"c": 1.2})
    ['c']
    >>> pinned_at_bounds({"k": 0.0}, {"k": (0.0, 1.0)})
    []
    """
    out = []
    for name, v in values.items():
        if name not in bounds:
            continue
        lo, hi = bounds[name]
        if at_bound(v, lo, hi) and (not zero_able(lo, hi) or (evidence or {}).get(name, math.inf) > PIN_EVIDENCE):
            out.append(name)
    return out


def at_bound(value: float, lo: float, hi: float) -> int:
    """``-1`` at the lower bound (not a zero one, :func:`pinned_at_bounds`), ``+1`` at the upper, ``0`` inside."""
    tol = 1e-3 * (hi - lo)
    if value >= hi - tol:
        return 1
    if value <= lo + tol and lo != 0.0:
        return -1
    return 0


# --------------------------------------------------------------------------- candidates


#: A candidate *materially* moves a tag when it changes the tag's training residual by more than this
#: many noise sigmas RMS; its validation NRMSE gain is averaged over those tags (:func:`score`).
MATERIAL_MOVE = 0.5


@dataclass(frozen=True)
class Candidate:
    """One effect on one target, screened (and maybe fitted).

    Attributes
    ----------
    effect, target
        The effect id and its target (a tag for sensor effects, a component instance otherwise).
    kind
        ``"sensor"`` or ``"process"``.
    stage
        ``"screen"`` (cheap transform or ramp), ``"fit"`` (patched and compiled) or ``"skipped"``.
    delta_bic
        BIC gain over the null on the training window (positive favours the candidate).
    validation_gain
        Relative fall of the NRMSE on the validation window, mean over the tags the
        candidate materially moves (:func:`score`; 0.7 = 70 % smaller).
    noise_gain
        Drop of the validation mean square residual of the affected tags, in noise variances (summed).
    noise_gains
        The same per affected tag.
    material
        Affected tags the candidate *materially* moves (training residual changed by more than
        :data:`MATERIAL_MOVE` noise sigmas RMS).
    tags
        Tags the candidate changes.
    values
        Fitted values (screening quantities such as ``bias`` or ``tau``, or the effect's parameters after a fit).
    nrmse_before, nrmse_after
        Validation NRMSE per affected tag, null and candidate.
    whiteness
        Lag-one autocorrelation of the candidate's training residual per affected tag.
    pinned
        Effect parameters at (within 0.1 % of the range of) one of their bounds.
    reason
        Why it was skipped, or a remark.
    """

    effect: str
    target: str
    kind: str
    stage: str
    delta_bic: float = math.nan
    validation_gain: float = math.nan
    noise_gain: float = math.nan
    tags: tuple[str, ...] = ()
    values: dict[str, float] = field(default_factory=dict)
    nrmse_before: dict[str, float] = field(default_factory=dict)
    nrmse_after: dict[str, float] = field(default_factory=dict)
    whiteness: dict[str, float] = field(default_factory=dict)
    pinned: tuple[str, ...] = ()
    reason: str = ""
    fit: Any = field(default=None, repr=False, compare=False)
    validation_residual: dict[str, np.ndarray] = field(default_factory=dict, repr=False, compare=False)
    training_residual: dict[str, np.ndarray] = field(default_factory=dict, repr=False, compare=False)
    noise_gains: dict[str, float] = field(default_factory=dict)
    material: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """An entry of ``diagnose --json``'s ``candidates``."""
        def num(x: float) -> float | None:
            return float(x) if x is not None and math.isfinite(x) else None

        return {"effect": self.effect, "target": self.target, "stage": self.stage,
                "delta_bic": num(self.delta_bic), "validation_gain": num(self.validation_gain),
                "noise_gain": num(self.noise_gain), "tags": list(self.tags), "material": list(self.material),
                "values": {k: num(v) for k, v in self.values.items()},
                "whiteness": {k: num(v) for k, v in self.whiteness.items()},
                **({"reason": self.reason} if self.reason else {})}


def training_score(where: WhereResult, k: int, training_after: Mapping[str, np.ndarray],
                   ) -> tuple[float, list[str], list[str]]:
    """ΔBIC of a candidate from its training residuals alone, its affected tags and the tags it moves
    materially (:func:`score`: the validation window does not enter the ΔBIC)."""
    before_t = {t: where.training.residual(t) for t in training_after}
    tags, material = [], []
    for t, r1 in training_after.items():
        d = np.asarray(r1) - before_t[t]
        d = d[np.isfinite(d)]
        move = float(np.sqrt(np.mean(d * d))) if d.size else 0.0
        if move > 0.01 * where.noise[t]:
            tags.append(t)
        if move > MATERIAL_MOVE * where.noise[t]:
            material.append(t)
    if not tags:
        tags = list(training_after)
    return delta_bic({t: before_t[t] for t in tags}, {t: training_after[t] for t in tags}, k), tags, material


def score(effect: str, target: str, kind: str, stage: str, where: WhereResult, k: int,
          training_after: Mapping[str, np.ndarray], validation_after: Mapping[str, np.ndarray],
          values: Mapping[str, float], *, pinned: Sequence[str] = (), fit: Any = None,
          reason: str = "") -> Candidate:
    """Score a candidate from its residuals on both windows (same grids as the null model's).

    A tag counts as affected when the candidate changes its training residual by
    more than a hundredth of its noise sigma RMS: those tags enter the ΔBIC, the
    noise gains and the check that no tag gets worse. The validation NRMSE gain
    (``validation_gain``) is the mean over the tags the candidate *materially*
    moves, by more than :data:`MATERIAL_MOVE` noise sigmas RMS (all affected tags
    when it moves none that far): a process effect reaches most tags of a plant
    through its controllers, and averaging the gain on the tags it is about with
    the near-zero changes of the rest would measure how many tags the plant has,
    not how much of the gap the effect closes.
    """
    va = where.validation
    dbic, tags, material = training_score(where, k, training_after)
    moved = tuple(material)
    material = material or tags
    nb, na, gains, ng, white, per_tag = {}, {}, [], 0.0, {}, {}
    for t in tags:
        r0 = va.residual(t)
        r1 = np.asarray(validation_after[t], dtype=float)
        nb[t] = nrmse_of(r0, va.measured[t])
        na[t] = nrmse_of(r1, va.measured[t])
        if nb[t] > 0 and t in material:
            gains.append(1.0 - na[t] / nb[t])
        per_tag[t] = noise_gain(r0, r1, where.noise[t])
        ng += per_tag[t]
        white[t] = ljung_box_lag1(training_after[t])
    return Candidate(effect, target, kind, stage, dbic, float(np.mean(gains)) if gains else math.nan, ng,
                     tuple(tags), dict(values), nb, na, white, tuple(pinned), reason, fit,
                     {t: np.asarray(validation_after[t], dtype=float) for t in tags},
                     {t: np.asarray(r, dtype=float) for t, r in training_after.items()}, per_tag,
                     tuple(t for t in moved if t in per_tag))


def joint(where: WhereResult, r_train: Mapping[str, np.ndarray], r_val: Mapping[str, np.ndarray] | None,
          extra_train: Mapping[str, np.ndarray] | None = None, extra_val: Mapping[str, np.ndarray] | None = None,
          jac: tuple[Mapping[str, np.ndarray], Mapping[str, np.ndarray]] | None = None, *,
          x: npt.ArrayLike | None = None,
          ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray], float, np.ndarray]:
    """Fit an effect's linear terms jointly with the spec's candidates (linearised) on training.

    Every output tag's residual *r_train* is fitted by ``J delta + T beta``: ``J``
    the null model's output sensitivity to the candidates, ``T`` the effect's
    columns (*extra_train*, tag -> ``(n, m)``; tags without are zero), noise-weighted,
    and the varying candidates' trajectories where the spec has some
    (:mod:`trackingbox.diagnose.varying`; refitted on validation, as the null's are).
    Returns ``beta``, the residuals after on training and on validation (the
    same coefficients with the validation window's ``J`` and ``T``), the
    weighted training cost and the candidates' step ``delta``. The step keeps the
    candidates inside their bounds (:func:`trackingbox.diagnose.residuals.step_bounds`), as
    the null model's polish does: an effect is never credited with what a candidate
    outside its bounds would explain. *x*: where the candidates are (default the null's).
    """
    j_train, j_val = jac if jac is not None else where.jacobian
    p = next(iter(j_train.values())).shape[1] if j_train else 0
    m = next(iter(extra_train.values())).shape[1] if extra_train else 0
    bounds = None
    problem = getattr(where, "problem", None)
    at = where.x if x is None else x
    if problem is not None and at is not None and len(problem.names) == p:
        bounds = step_bounds(problem, at, extra=m)
    fit = fit_windows(r_train, r_val, (j_train, j_val), where.noise, bounds=bounds, extra_train=extra_train,
                      extra_val=extra_val, varying=getattr(where, "varying", None) if p else None,
                      x=at if p else None)
    return fit.beta, fit.after_train, fit.after_valid, fit.cost, fit.delta


def freed_evidence(where: WhereResult, residuals: tuple[Mapping[str, np.ndarray], Mapping[str, np.ndarray]],
                   column: tuple[Mapping[str, np.ndarray], Mapping[str, np.ndarray]], side: int, *,
                   x: npt.ArrayLike | None = None) -> float:
    """:func:`bound_evidence` of one effect parameter at a bound, linearised: its move beyond the bound fitted.

    *residuals*: training and validation residuals with the parameter at its bound; *column*: per
    window, tag -> ``(n,)`` sensitivity of the outputs to the parameter; *side*: ``+1`` at its upper
    bound, ``-1`` at its lower. Both fits refit the spec's candidates (and the varying ones) with
    :func:`joint`, the freed one with the parameter's column as an unbounded term. 0 when the free
    move points back inside the bounds (the bound holds nothing back), or the ratio falls.
    """
    tags = list(residuals[0])
    n = {t: len(residuals[0][t]) for t in tags}
    nv = {t: len(residuals[1][t]) for t in tags}
    col_t = {t: np.asarray(column[0].get(t, np.zeros(n[t])), dtype=float).reshape(-1, 1) for t in tags}
    col_v = {t: np.asarray(column[1].get(t, np.zeros(nv[t])), dtype=float).reshape(-1, 1) for t in tags}
    _, held, _, _, _ = joint(where, residuals[0], residuals[1], x=x)
    beta, freed, _, _, _ = joint(where, residuals[0], residuals[1], col_t, col_v, x=x)
    if beta.size == 0 or not side * float(beta[0]) > 0.0:
        return 0.0
    # the joint fit lowers the noise-weighted cost; the ratio over effective samples may still fall where it
    # trades one tag against another (a coarse linearisation far beyond the bound): no evidence either
    return max(bound_evidence(held, freed), 0.0)
