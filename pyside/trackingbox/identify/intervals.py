"""Confidence intervals of estimated parameters, with the residuals' own noise and autocorrelation.

At the estimate ``θ̂`` on the training window the twin's residuals ``r`` and
sensitivities ``J`` are taken once (:mod:`trackingbox.identify.model`). The
estimator minimises the mean NRMSE over the tags, whose first-order condition
is a weighted least-squares one, ``Σ_tag w_tag J_tagᵀ r_tag = 0`` with
``w_tag = 1 / (NRMSE_tag · range_tag² · n_tag)`` at ``θ̂``. In the scaled
coordinates ``z`` (``ln θ`` where the bounds are positive, else ``θ / range``):

* ``A = Σ_tag w_tag J_tagᵀ J_tag`` (the cost's curvature),
* the score contributions ``g_t = Σ_tag w_tag r_tag,t J_tag,t``, one per time step,
  and their long-run covariance ``B`` (equal-weighted cosine estimator with
  ``ν`` terms, :func:`trackingbox.identify.noise.long_run_covariance`), which
  takes each tag's noise level *and* the residuals' autocorrelation from the
  residuals,
* the sandwich covariance ``C = A⁺ B A⁺``.

**Linearised interval** of a functional ``c = aᵀz`` (a parameter: ``a = e_j``;
a determined combination: its exponents): ``ĉ ± t_ν · sqrt(aᵀCa)``, back in the
parameter's units (``exp`` for log coordinates, so it stays positive and may be
asymmetric). ``t_ν`` is Student's quantile with the cosine estimator's ``ν``
degrees of freedom (its variance estimate is ``χ²_ν/ν`` of the truth): fewer
where the residuals stay correlated for long. The *effective sample size*
``N · aᵀC₀a / aᵀCa`` (``C₀``: the sandwich without the autocorrelation, ``N``:
the time steps) is reported beside it.

**When the linearisation is poor.** At both ends of the linearised interval the
cost is evaluated (one run each, the other parameters moved as the
linearisation predicts; every run of this check and of the profile at the
solver tolerance of the central differences, 1e-9: at the estimation's 1e-6 the
integrator's own variation between two runs moved the cost by about a tenth of
the rise it is compared with, on the thermal wall) and turned into the *adjusted deviance*
``D(c) = (SSR_w(c) - SSR_w(ĉ)) · aᵀA⁺a / aᵀCa``, which a quadratic cost makes
exactly ``t_ν²`` there. If it differs from ``t_ν²`` by more than
:data:`NONLINEARITY_TOLERANCE` at either end (or an end lies beyond a bound),
the interval is the **profile likelihood** one instead: ``{c : D(c) ≤ t_ν²}``,
each ``D(c)`` minimised over the other parameters (the linear prediction, then
up to :data:`PROFILE_STEPS` Gauss-Newton steps with the Jacobian at ``θ̂``),
its ends found by the secant rule on ``sqrt(D)``. The magnitude adjustment
``aᵀA⁺a / aᵀCa`` is the one a quasi-likelihood needs for a scalar parameter when
the residuals are correlated (the naive deviance overstates the information by
exactly the sandwich's ratio).

**The measured inputs' noise.** The twin is driven by *measured* inputs; their
noise adds variance to the residuals (which the sandwich takes from them) and can
bias an estimate, which no residual shows. On the heat-exchanger bench with the
hot side's volume estimated beside the heat-transfer coefficient (flows measured
with 1 % noise, a 2 min residence time sampled every 10 s) the volume came out
6 % high on average over 50 seeds and 24 % high on one scenario, and the
intervals without the inputs' noise held the plant's value in 29 of 50 seeds.
:mod:`trackingbox.identify.inputs` reads each input's noise from its samples and
extrapolates the bias from what one and two more doses of it do at the estimate;
where its runs fit in a third of the budget the interval is moved by it and
widened by its Monte Carlo error, and its note says so
(``scripts/bench_uncertainty`` measures it: ``hx2``). Where they do not fit (many
parameters with central differences: ``16 (2n + 1)`` runs) the JSON says the
inputs' noise was not propagated.

**Not determined.** A parameter in a direction the data do not determine
(:mod:`trackingbox.identify.structure`, with ``C``) gets no interval: it is
"not determined (with …)", and the combinations that *are* determined get theirs.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from scipy.stats import t as student_t

from ..errors import EstimationError, TrackingError
from ..simulation.models import close_models
from . import structure as st
from .analysis import Combination, Finding, finding_text, name_findings
from .model import FD_TOLERANCE, Evaluation, TwinWindow, safe, window_for
from .inputs import PAIRS, InputBias, input_bias
from .lackfit import LackOfFit
from .noise import effective_samples, lag1, long_run_covariance

log = logging.getLogger(__name__)

#: Default confidence level.
DEFAULT_LEVEL = 0.95
#: The linearisation is accepted when the adjusted deviance at both ends of its interval is within
#: this fraction of its predicted value ``t²`` (0.1: the ends move by about 5 %).
NONLINEARITY_TOLERANCE = 0.1
#: Gauss-Newton steps (with the Jacobian at the estimate) minimising the cost over the other
#: parameters at each profile point.
PROFILE_STEPS = 2
#: Secant steps per end of a profile interval.
PROFILE_ITERATIONS = 6
#: Most twin runs the profiles of one estimate may take (the linearised interval is kept, with
#: that said, for the rest).
PROFILE_BUDGET = 240
#: Relative accuracy of a profile interval's ends (in ``sqrt(D)``).
PROFILE_TOLERANCE = 0.02


@dataclass(frozen=True)
class Interval:
    """A confidence interval of one parameter or one determined combination.

    Attributes
    ----------
    name
        The parameter, or the combination's text (``R1·C``).
    estimate
        The estimate (the combination's value at the estimate).
    lower, upper
        The interval (None when not determined).
    method
        ``"linearised"``, ``"profile"`` or ``"not determined"``.
    level
        The confidence level.
    standard_error
        Of the scaled coordinate (relative for log-scaled parameters).
    dof
        Degrees of freedom of the t quantile (the cosine terms of the long-run covariance).
    effective_samples
        ``N · naive / sandwich`` variance ratio of this functional (see the module).
    deviance
        The adjusted deviance at the linearised interval's lower and upper ends over its
        predicted value (1 for a quadratic cost); NaN where not evaluated.
    at_bound
        The interval's lower / upper end is a parameter bound (the data do not exclude it).
    combination
        For a combination: what it combines.
    note
        Why not determined, why not profiled, or what bounded it.
    """

    name: str
    estimate: float
    lower: float | None
    upper: float | None
    method: str
    level: float
    standard_error: float = math.nan
    dof: float = math.nan
    effective_samples: float = math.nan
    deviance: tuple[float, float] = (math.nan, math.nan)
    at_bound: tuple[bool, bool] = (False, False)
    combination: Combination | None = None
    note: str = ""

    @property
    def determined(self) -> bool:
        return self.method != "not determined"

    def text(self, spec: str = ".5g") -> str:
        """``910.2 [884.1, 937.4] (95 %, linearised)`` or ``not determined (with …)``."""
        if not self.determined:
            return self.note or "not determined"
        lo = f"{self.lower:{spec}}" if self.lower is not None else "?"
        hi = f"{self.upper:{spec}}" if self.upper is not None else "?"
        bound = " (a bound: the data do not exclude it)" if any(self.at_bound) else ""
        return f"{self.estimate:{spec}} [{lo}, {hi}] ({100 * self.level:g} %, {self.method}){bound}"

    def covers(self, value: float) -> bool | None:
        """Whether *value* lies in the interval (None when not determined)."""
        if not self.determined or self.lower is None or self.upper is None:
            return None
        return bool(self.lower <= value <= self.upper)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "name": self.name, "estimate": _jf(self.estimate), "lower": _jf(self.lower), "upper": _jf(self.upper),
            "method": self.method, "level": self.level, "standard_error": _jf(self.standard_error),
            "dof": _jf(self.dof), "effective_samples": _jf(self.effective_samples),
            "deviance_ratio": [_jf(d) for d in self.deviance], "at_bound": list(self.at_bound),
            "text": self.text()}
        if self.combination is not None:
            out["combination"] = self.combination.to_json()
        if self.note:
            out["note"] = self.note
        return out


def _jf(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else float(v)


@dataclass(frozen=True)
class TagNoise:
    """What the residuals of one tag say about its noise at the estimate."""

    rms: float
    lag1: float
    samples: int
    effective_samples: float

    def to_json(self) -> dict[str, Any]:
        return {"rms": _jf(self.rms), "lag1": _jf(self.lag1), "samples": self.samples,
                "effective_samples": _jf(self.effective_samples)}


@dataclass(frozen=True)
class Uncertainty:
    """What :func:`uncertainty` found at an estimate.

    Attributes
    ----------
    level
        Confidence level.
    parameters
        One :class:`Interval` per estimated parameter (spec order).
    combinations
        Intervals of the combinations the data determine where some parameters are not.
    findings
        The groups of parameters the data cannot tell apart (at the estimate, with the
        residuals' noise).
    names, scaling
        The parameters and their scaled coordinates (``"log"`` / ``"range"``).
    correlation
        Correlation matrix of the scaled parameters (sandwich covariance; a direction the
        data do not determine at all shows as +-1).
    noise
        Tag -> :class:`TagNoise`.
    sandwich
        The long-run covariance's cosine terms, the scores' integral time scale (time steps)
        and the number of time steps.
    sensitivities
        ``("exact" | "fd", why not exact)``.
    runs
        Twin runs made.
    lack_of_fit
        The tags the twin disagrees with beyond their noise at the estimate (:mod:`.lackfit`): the
        intervals assume there are none. None where not checked.
    """

    level: float
    parameters: tuple[Interval, ...]
    combinations: tuple[Interval, ...]
    findings: tuple[Finding, ...]
    names: tuple[str, ...]
    scaling: tuple[str, ...]
    correlation: np.ndarray = field(repr=False, compare=False)
    noise: dict[str, TagNoise] = field(default_factory=dict)
    sandwich: dict[str, float] = field(default_factory=dict)
    sensitivities: tuple[str, str] = ("", "")
    runs: int = 0
    inputs: InputBias | None = None
    inputs_note: str = ""
    lack_of_fit: LackOfFit | None = None

    def interval(self, name: str) -> Interval:
        for iv in self.parameters + self.combinations:
            if iv.name == name:
                return iv
        raise KeyError(name)

    def to_json(self) -> dict[str, Any]:
        return {
            "level": self.level,
            "parameters": {iv.name: iv.to_json() for iv in self.parameters},
            "combinations": [iv.to_json() for iv in self.combinations],
            "findings": [f.to_json() for f in self.findings],
            "scaling": dict(zip(self.names, self.scaling)),
            "correlation": {"names": list(self.names),
                            "matrix": [[_jf(v) for v in row] for row in np.asarray(self.correlation)]},
            "noise": {t: n.to_json() for t, n in self.noise.items()},
            "sandwich": dict(self.sandwich),
            "sensitivities": {"method": self.sensitivities[0], "reason": self.sensitivities[1]},
            "runs": self.runs,
            "inputs_noise": ({**self.inputs.to_json(), "names": list(self.names)} if self.inputs is not None
                             else {"note": self.inputs_note}),
            "lack_of_fit": self.lack_of_fit.to_json() if self.lack_of_fit is not None else None,
            "method": ("linearised from the cost's curvature with the residuals' own noise and autocorrelation "
                       "(sandwich with an equal-weighted cosine long-run covariance, Student t on its terms); profile likelihood "
                       f"where the adjusted deviance at an end of the linearised interval is off its prediction "
                       f"by more than {NONLINEARITY_TOLERANCE:g}"),
        }


# --------------------------------------------------------------------------- the computation


@dataclass(frozen=True)
class Sandwich:
    """The pieces of the sandwich covariance (scaled coordinates; see the module docstring).

    Attributes
    ----------
    A, A_pinv
        ``Σ_tag w_tag J_tagᵀ J_tag`` and its pseudo-inverse (directions below the rank
        tolerance left out).
    C, C0
        ``A⁺ B A⁺`` with the scores' long-run covariance ``B``, and with their lag-0
        covariance only (as if the residuals were white).
    steps
        Time steps with at least one residual.
    terms
        Cosine terms of the long-run covariance: the t quantile's degrees of freedom.
    integral_scale
        The scores' integral time scale (time steps).
    """

    A: np.ndarray
    A_pinv: np.ndarray
    C: np.ndarray
    C0: np.ndarray
    steps: int
    terms: float
    integral_scale: float


def sandwich(jacobians: Mapping[str, np.ndarray], residuals: Mapping[str, np.ndarray],
             index: Mapping[str, np.ndarray], weights: Mapping[str, float], steps: int,
             terms: int | None = None) -> Sandwich:
    """The sandwich covariance of a weighted least-squares estimate from its residuals and Jacobians.

    *jacobians*, *residuals*, *index*: per tag the Jacobian rows (scaled coordinates), the
    residuals and their positions on a grid of *steps* time steps; *weights*: per tag.
    *terms*: the cosine terms (default :func:`~trackingbox.identify.noise.cosine_terms`).
    """
    tags = list(residuals)
    n = int(np.asarray(jacobians[tags[0]]).shape[1]) if tags else 0
    g = np.zeros((steps, n))
    has = np.zeros(steps, dtype=bool)
    A = np.zeros((n, n))
    for tag in tags:
        J = np.asarray(jacobians[tag], dtype=float)
        r = np.asarray(residuals[tag], dtype=float)
        w = float(weights[tag])
        A += w * J.T @ J
        np.add.at(g, index[tag], (w * r)[:, None] * J)
        has[index[tag]] = True
    g = g[has]
    N = int(g.shape[0])
    # A's pseudo-inverse: numerically null directions (below the rank tolerance) have no information
    lam, V = np.linalg.eigh(A)
    keep = lam > (st.RANK_RTOL ** 2) * max(float(lam.max()), 0.0) if lam.size else np.zeros(0, dtype=bool)
    P = V[:, keep]
    A_pinv = (P / lam[keep]) @ P.T
    # the scores' long-run covariance in the directions A sees (a null direction's scores carry no
    # information and would only add the integrator's noise)
    gp = g @ P
    omega, info = long_run_covariance(gp, terms=terms)
    B = P @ (N * omega) @ P.T
    B0 = P @ (gp.T @ gp) @ P.T
    return Sandwich(A, A_pinv, A_pinv @ B @ A_pinv, A_pinv @ B0 @ A_pinv, N, float(info["terms"]),
                    float(info["integral_scale"]))


def linear_interval(a: np.ndarray, sw: Sandwich, c_hat: float, level: float) -> tuple[float, float, float, float]:
    """The linearised interval of ``c = aᵀz`` at ``ĉ``: ``(lower, upper, standard error, t quantile)``."""
    se = math.sqrt(max(float(a @ sw.C @ a), 0.0))
    tq = float(student_t.ppf(0.5 + level / 2.0, sw.terms))
    return c_hat - tq * se, c_hat + tq * se, se, tq


class _Coordinates:
    """Scaled coordinates ``z`` of the parameters (log or range) and back."""

    def __init__(self, scaling: st.Scaling, lower: np.ndarray, upper: np.ndarray, x_hat: np.ndarray) -> None:
        self.kinds = scaling.kinds
        self.log = np.array([k == "log" for k in scaling.kinds])
        self.span = upper - lower
        self.lower, self.upper = lower, upper
        self.z_hat = self.to_z(x_hat)
        self.z_lo, self.z_hi = self.to_z(lower), self.to_z(upper)

    def to_z(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.log, np.log(np.where(self.log, x, 1.0)), x / self.span)

    def to_x(self, z: np.ndarray) -> np.ndarray:
        return np.where(self.log, np.exp(np.where(self.log, z, 0.0)), z * self.span)

    def clip(self, z: np.ndarray) -> np.ndarray:
        return np.clip(z, self.z_lo, self.z_hi)


class _Profile:
    """The cost along one functional ``aᵀz`` (see the module docstring)."""

    def __init__(self, tw: TwinWindow, coords: _Coordinates, weights: Mapping[str, float], Jw: np.ndarray,
                 A_pinv: np.ndarray, ssr0: float, budget: list[int],
                 progress: Callable[[int, int], None] | None = None) -> None:
        self.tw, self.coords, self.weights = tw, coords, dict(weights)
        self.Jw, self.A_pinv, self.ssr0, self.budget = Jw, A_pinv, ssr0, budget
        self.total, self.progress = budget[0], progress

    def _run(self, z: np.ndarray) -> tuple[float, np.ndarray] | None:
        if self.budget[0] <= 0:
            raise _OutOfBudget
        self.budget[0] -= 1
        if self.progress is not None:  # runs so far, against the budget (most runs end well before it)
            self.progress(self.total - self.budget[0], self.total)
        try:
            ev = self.tw.outputs(self.coords.to_x(z), tolerance=FD_TOLERANCE)
        except TrackingError as exc:
            log.info("profile run failed at %s: %s", self.coords.to_x(z), exc)
            return None
        res = ev.residuals()
        rw = np.concatenate([res[t] * math.sqrt(self.weights[t]) for t in res])
        return float(rw @ rw), rw

    def cost(self, a: np.ndarray, c: float, *, steps: int) -> tuple[float, float]:
        """``(SSR_w, c reached)`` at ``aᵀz = c``, the others as predicted, then *steps* Gauss-Newton steps."""
        coords = self.coords
        Aa = self.A_pinv @ a
        z = coords.z_hat + Aa / float(a @ Aa) * (c - float(a @ coords.z_hat))
        z = coords.clip(z)
        found = self._run(z)
        if found is None:
            return math.inf, float(a @ z)
        ssr, rw = found
        if steps and a.size > 1:
            # the other parameters: minimise |rw + Jw d|^2 with a^T d = 0 (Jacobian at the estimate)
            _, _, vt = np.linalg.svd(a[None, :])
            N = vt[1:].T
            for _ in range(steps):
                w, *_ = np.linalg.lstsq(self.Jw @ N, -rw, rcond=None)
                z_new = coords.clip(z + N @ w)
                trial = self._run(z_new)
                if trial is None or trial[0] >= ssr:
                    break
                z, (ssr, rw) = z_new, trial
        return ssr, float(a @ z)


class _OutOfBudget(Exception):
    pass


def uncertainty(spec: Any, estimate: Mapping[str, float], *, level: float = DEFAULT_LEVEL, method: str = "auto",
                warmup: float | None = None, profile: bool = True, budget: int = PROFILE_BUDGET,
                progress: Callable[[int, int], None] | None = None) -> Uncertainty:
    """Confidence intervals of the spec's ``[[parameters]]`` at *estimate* (see the module docstring).

    Parameters
    ----------
    spec
        A loaded spec.
    estimate
        Parameter -> estimated value (every one of the spec's ``[[parameters]]``).
    level
        Confidence level, in (0, 1).
    method
        Sensitivities: ``"auto"``, ``"exact"`` or ``"fd"`` (see :mod:`trackingbox.identify.model`).
    warmup
        The estimation's warm-up (s).
    profile
        Use the profile likelihood where the linearisation is poor (else only say so).
    budget
        Most twin runs for the linearity checks and profiles.
    progress
        ``progress(runs, budget)`` after each of those runs (each can take seconds on a day of data).
    """
    if not (isinstance(level, float | int) and 0.0 < float(level) < 1.0):
        raise EstimationError(f"uncertainty: level must be in (0, 1), not {level!r}")
    try:
        problem, window = window_for(spec, warmup=warmup)
        missing = [n for n in problem.names if n not in estimate]
        if missing:
            raise EstimationError(f"uncertainty: no estimate of {', '.join(missing)}")
        x_hat = np.array([float(estimate[n]) for n in problem.names])
        tw = TwinWindow(problem, window, method)  # type: ignore[arg-type]
        ev = safe(lambda: tw.sensitivities(x_hat), "uncertainty at the estimate")
        return _uncertainty(problem, window, tw, ev, x_hat, float(level), profile, budget, progress)
    finally:
        close_models()


def _weights(ev: Evaluation) -> dict[str, float]:
    """The mean-NRMSE estimator's weights at the estimate: ``1 / (NRMSE · range² · n)`` per tag."""
    res = ev.residuals()
    out = {}
    for tag, r in res.items():
        n = max(r.size, 1)
        scale = _span(ev.measured[tag]) if r.size else 1.0
        nr = math.sqrt(float(np.mean(r * r))) / scale if r.size else 0.0
        out[tag] = 1.0 / (max(nr, 1e-12) * scale * scale * n)
    return out


def _uncertainty(problem: Any, window: Any, tw: TwinWindow, ev: Evaluation, x_hat: np.ndarray, level: float,
                 profile: bool, budget: int, progress: Callable[[int, int], None] | None = None
                 ) -> Uncertainty:
    names = list(problem.names)
    n = len(names)
    scaling = st.parameter_scaling(x_hat, problem.lower, problem.upper)
    coords = _Coordinates(scaling, problem.lower, problem.upper, x_hat)
    weights = _weights(ev)
    res = ev.residuals()
    assert ev.jacobian is not None
    sw = sandwich({t: ev.jacobian[t] * scaling.factors[None, :] for t in res}, res, ev.index, weights,
                  window.time.size)
    A_pinv, C, C0, N, info = sw.A_pinv, sw.C, sw.C0, sw.steps, {"terms": sw.terms,
                                                                 "integral_scale": sw.integral_scale}
    Jw = np.concatenate([ev.jacobian[t] * scaling.factors[None, :] * math.sqrt(weights[t]) for t in res], axis=0)
    structure = st.analyse(Jw, names, scaling.widths, covariance=C)
    findings = [_with_message(f) for f in name_findings(structure, scaling, x_hat, [], ev, names)]
    # the measured inputs' noise: its bias, where the runs fit in a third of the budget
    per_run = 4 * (1 if tw.method == "exact" else 2 * n + 1)  # two doses, antithetic
    ib: InputBias | None = None
    inputs_note = ""
    if not window.inputs:
        inputs_note = "the twin has no measured inputs"
    elif PAIRS * per_run > budget / 3:
        inputs_note = (f"the inputs' noise was not propagated: {PAIRS * per_run} twin runs "
                       f"({tw.method} sensitivities) exceed a third of the budget of {budget}")
    else:
        before = tw.runs
        try:
            ib = safe(lambda: input_bias(tw, ev, scaling.factors, weights), "the inputs' noise")
        except EstimationError as exc:  # e.g. a noisy dose drove an input out of the twin's range
            log.warning("uncertainty: the inputs' noise was not propagated: %s", exc)
            inputs_note = f"the inputs' noise was not propagated: {exc}"
        budget -= tw.runs - before
        if ib is None and not inputs_note:
            inputs_note = "no noise found on the measured inputs"
    prof = _Profile(tw, coords, weights, Jw, A_pinv, math.nan, [int(budget) + 1], progress)
    # the reference cost from a run like the profile's own (the sensitivity run integrates differently)
    base = prof._run(coords.z_hat)
    if base is None:
        raise EstimationError("uncertainty: the twin failed at the estimate")
    prof.ssr0 = ssr0 = base[0]
    grouped = {p: f for f in findings for p in f.parameters}

    def functional(a: np.ndarray, name: str, value: float, to_value: Any, bounds: tuple[float, float],
                   combination: Combination | None = None) -> Interval:
        var, var0 = float(a @ C @ a), float(a @ C0 @ a)
        n_eff = N * min(1.0, var0 / var) if var > 0 else float(N)
        dof = float(info["terms"])
        c_hat = float(a @ coords.z_hat)
        lo_end, hi_end, se, tq = linear_interval(a, sw, c_hat, level)
        kappa = float(a @ A_pinv @ a) / var if var > 0 else 1.0
        ends = [lo_end, hi_end]
        note = ""
        deviance = [math.nan, math.nan]
        method = "linearised"
        beyond = [ends[0] < bounds[0], ends[1] > bounds[1]]
        try:
            for k in (0, 1):
                ssr, reached = prof.cost(a, float(np.clip(ends[k], *bounds)), steps=0)
                d = (ssr - ssr0) * kappa
                deviance[k] = d / (tq * tq) if not beyond[k] else math.nan
            poor = any(beyond) or any(not (abs(q - 1.0) <= NONLINEARITY_TOLERANCE) for q in deviance
                                      if not math.isnan(q))
            if poor and profile:
                ends = [_profile_end(prof, a, c_hat, tq, se, kappa, bounds, -1),
                        _profile_end(prof, a, c_hat, tq, se, kappa, bounds, +1)]
                method = "profile"
            elif poor:
                note = "the linearisation is poor here (profile not asked for)"
        except _OutOfBudget:
            note = f"profile not computed: the budget of {budget} runs is spent"
        if ib is not None:
            # the inputs' noise biases the estimate by aᵀb (trackingbox.identify.inputs): the interval is moved
            # by it and widened by its jackknife error; where the extrapolation is not to be trusted it covers
            # a bias from aᵀd1 to 2 aᵀd1 (d1: the first dose's step, a lower bound where the bias saturates)
            involved = [ib.kinds[j] for j in np.flatnonzero(a)]
            mc = tq * math.sqrt(max(float(a @ ib.covariance @ a), 0.0))
            if "bounds" in involved:
                shift = float(a @ ib.first)
                ends = [ends[0] - max(2.0 * shift, shift) - mc, ends[1] - min(2.0 * shift, shift) + mc]
            else:
                shift = float(a @ ib.bias)
                ends = [ends[0] - shift - mc, ends[1] - shift + mc]
            if abs(shift) > 0.1 * max(se, 1e-300):
                note = (note + "; " if note else "") + (
                    f"the measured inputs' noise biases the estimate by about {_shift_text(shift, a, scaling)}"
                    + (" or more" if "bounds" in involved else "") + ": the interval is moved for it")
        at_bound = (ends[0] <= bounds[0] + 1e-12 * max(1.0, abs(bounds[0])),
                    ends[1] >= bounds[1] - 1e-12 * max(1.0, abs(bounds[1])))
        ends = [float(np.clip(ends[0], *bounds)), float(np.clip(ends[1], *bounds))]
        return Interval(name, value, to_value(ends[0]), to_value(ends[1]), method, level, se, dof, n_eff,
                        (deviance[0], deviance[1]), at_bound, combination, note)

    intervals: list[Interval] = []
    for j, name in enumerate(names):
        if name in grouped:
            f = grouped[name]
            others = [p for p in f.parameters if p != name]
            what = (f"only {st.listing([c.text for c in f.determined])} {'is' if len(f.determined) == 1 else 'are'}"
                    if f.determined else "no combination of them is")
            intervals.append(Interval(name, float(x_hat[j]), None, None, "not determined", level,
                                      note=f"not determined (with {st.listing(others)}: {what})" if others else
                                      f"not determined ({what})"))
            continue
        a = np.zeros(n)
        a[j] = 1.0
        to_value = (math.exp if scaling.kinds[j] == "log" else (lambda z, s=coords.span[j]: z * s))
        iv = functional(a, name, float(x_hat[j]), to_value, (float(coords.z_lo[j]), float(coords.z_hi[j])))
        if not (iv.upper is None or iv.lower is None) and \
                (coords.to_z(np.full(n, iv.upper))[j] - coords.to_z(np.full(n, iv.lower))[j]) \
                > 2.0 * st.DETERMINED_FRACTION * scaling.widths[j]:
            iv = Interval(name, iv.estimate, None, None, "not determined", level, iv.standard_error, iv.dof,
                          iv.effective_samples, iv.deviance, iv.at_bound, None,
                          f"not determined: its {100 * level:g} % interval [{iv.lower:.5g}, {iv.upper:.5g}] spans "
                          "more than half of its bounds")
        intervals.append(iv)
    combos: list[Interval] = []
    values = dict(zip(names, map(float, x_hat)))
    for f in findings:
        for comb in f.determined:
            a = np.zeros(n)
            for p, e in comb.terms.items():
                j = names.index(p)
                a[j] = e if comb.kind == "product" else e * coords.span[j]
            lo_b, hi_b = _functional_bounds(a, coords)
            to_value = math.exp if comb.kind == "product" else (lambda z: z)
            combos.append(functional(a, comb.text, comb.value(values), to_value, (lo_b, hi_b), comb))
    noise = {tag: TagNoise(float(np.sqrt(np.mean(r * r))) if r.size else math.nan, lag1(_on_grid(r, ev.index[tag])),
                           int(r.size), effective_samples(_on_grid(r, ev.index[tag]))) for tag, r in res.items()}
    return Uncertainty(level, tuple(intervals), tuple(combos), tuple(findings), tuple(names), scaling.kinds,
                       structure.correlation, noise, {**info, "time_steps": float(N)}, (tw.method, tw.reason),
                       tw.runs, ib, inputs_note)


def _shift_text(shift: float, a: np.ndarray, scaling: st.Scaling) -> str:
    """A bias in scaled coordinates as words: ``+6.2 %`` (log-scaled) or ``+0.031 of its range``."""
    logs = [scaling.kinds[j] == "log" for j in np.flatnonzero(a)]
    if all(logs):
        return f"{100.0 * math.expm1(shift):+.2g} %"
    return f"{shift:+.2g} of its range"


def _with_message(f: Finding) -> Finding:
    return replace(f, message=finding_text(f))


def _span(values: np.ndarray) -> float:
    """The range of *values*, as the estimation's NRMSE takes it (``max(|mean|, 1)`` for a constant).

    >>> _span(np.array([1.0, 3.0])), _span(np.array([5.0, 5.0]))
    (2.0, 5.0)
    """
    span = float(np.max(values) - np.min(values))
    return span if span > 0.0 else max(abs(float(np.mean(values))), 1.0)


def _on_grid(r: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Residuals back on their grid positions (NaN between), for autocorrelation."""
    if r.size == 0:
        return r
    out = np.full(int(index.max()) + 1, np.nan)
    out[index] = r
    return out


def _functional_bounds(a: np.ndarray, coords: _Coordinates) -> tuple[float, float]:
    """Range of ``aᵀz`` over the bound box."""
    lo = float(np.sum(np.where(a > 0, a * coords.z_lo, a * coords.z_hi)))
    hi = float(np.sum(np.where(a > 0, a * coords.z_hi, a * coords.z_lo)))
    return lo, hi


def _profile_end(prof: _Profile, a: np.ndarray, c_hat: float, tq: float, se: float, kappa: float,
                 bounds: tuple[float, float], side: int) -> float:
    """The end of the profile interval on *side* (-1: lower, +1: upper): ``D(c) = t²`` by the secant rule on ``sqrt(D)``."""
    limit = bounds[0] if side < 0 else bounds[1]
    pts = [(c_hat, 0.0)]  # (c, sqrt(D))
    c = c_hat + side * tq * se
    for _ in range(PROFILE_ITERATIONS):
        c = float(np.clip(c, *bounds))
        ssr, reached = prof.cost(a, c, steps=PROFILE_STEPS)
        root = math.sqrt(max((ssr - prof.ssr0) * kappa, 0.0)) if math.isfinite(ssr) else math.inf
        pts.append((reached, root))
        if abs(root - tq) <= PROFILE_TOLERANCE * tq:
            return reached
        if root < tq and abs(reached - limit) <= 1e-9 * max(1.0, abs(limit)):
            return limit  # the bound is reached inside the interval
        (c1, r1), (c2, r2) = pts[-2], pts[-1]
        if not math.isfinite(r2):
            c = 0.5 * (c1 + c2)
            pts.pop()
            continue
        below = [p for p in pts if p[1] < tq]
        above = [p for p in pts if p[1] >= tq]
        if above and below:  # bracketed: interpolate between the closest on each side
            cb = min(below, key=lambda p: abs(p[0] - c2))
            ca = min(above, key=lambda p: abs(p[0] - c2))
            c = cb[0] + (tq - cb[1]) * (ca[0] - cb[0]) / (ca[1] - cb[1])
        else:
            slope = (r2 - r1) / (c2 - c1) if c2 != c1 else 0.0
            c = c2 + (tq - r2) / slope if slope * side > 0 else c_hat + 2.0 * (c2 - c_hat)
    return pts[-1][0]
