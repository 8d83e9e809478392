"""The measured inputs' noise in an estimate: how much it biases the estimate, from the inputs' own data.

The twin is driven by the *measured* inputs. Their noise ``e_u`` reaches the
residuals through the twin (``J_u e_u``), and there it does two things:

* it adds variance to the residuals, which the sandwich covariance of
  :mod:`trackingbox.identify.intervals` already takes from them (the residuals
  hold it, with its autocorrelation);
* it **biases** the estimate wherever a parameter changes how much of the
  input noise the twin passes on: a larger volume smooths a noisy flow more, so
  it lowers the cost by ``E‖J_u(θ) e_u‖²`` and the estimate drifts towards it.
  No residual shows this (errors in variables).

**The noise of each input** is taken from its own samples: for white noise on
a signal that is smooth against the sample time, the second differences hold
``6σ²`` of it and almost nothing of the signal (a ramp has none); their median
absolute deviation (robust to the signal's steps) gives
``σ = 1.4826 · MAD(Δ²u) / √6`` (:func:`input_noise`). It over-states the noise
of an input whose own moves are fast against the sample time (that makes the
correction larger, never silent), and under-states noise correlated from one
sample to the next.

**The bias** (:func:`input_bias`) is extrapolated from what more of the same
noise does to the estimate (simulation-extrapolation, SIMEX): ``K`` antithetic
pairs ``u ± √λ δ_k`` (``δ_k`` white with the estimated ``σ`` per input) at the
doses ``λ = 1`` and ``2`` (the same draws), each run with the sensitivities at
the estimate and giving the Gauss-Newton step of its own fit,
``Δz = -A_k⁺ g_k`` (``g_k = Σ_tag w_tag J_kᵀ r_k`` in the scaled coordinates of
the intervals). In a pair's mean the part linear in ``δ`` cancels exactly; the
means less the step at the measured inputs are ``d1`` and ``d2``, what one and
two more doses add. The bias does not grow linearly with the noise: where a
parameter sets how much noise the twin passes on, the noise's own share of the
cost bends the cost too (a filter passes a variance ``∝ 1/τ``), and the bias
saturates (on the heat-exchanger bench with the hot side's volume estimated,
``d1`` alone was 0.47-0.59 of the estimate's actual error in ``ln V1`` on seeds
0, 4, 11 and 19). :func:`extrapolate` fits the rational extrapolant
``θ(λ) = a + β/(c + λ)`` (Cook and Stefanski's, exact for regression dilution) through
``0, d1, d2`` and takes ``-θ(-1)``; where its pole would lie in ``[-1, 0]`` the
interval instead covers a bias from ``d1`` to ``2 d1``. The interval is moved by
the bias and widened by its jackknife error over the pairs
(:mod:`trackingbox.identify.intervals`).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..errors import EstimationError

#: Antithetic pairs of noise realisations (2 sensitivity runs each).
PAIRS = 4
#: Inputs whose noise is below this fraction of their own range over the window are taken as exact.
NEGLIGIBLE = 1e-6


def input_noise(values: np.ndarray) -> float:
    """The standard deviation of an input's white measurement noise, from its samples.

    ``1.4826 · MAD(Δ²u) / √6`` (see the module); 0 for fewer than 4 samples.

    >>> rng = np.random.default_rng(1)
    >>> t = np.arange(5000.0)
    >>> u = np.where(t < 2500, 1.0, 1.3) + 1e-4 * t + rng.normal(0.0, 0.01, t.size)
    >>> round(input_noise(u), 3)
    0.01
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size < 4:
        return 0.0
    d = np.diff(v, 2)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(6.0))


@dataclass(frozen=True)
class InputBias:
    """The inputs' noise and the bias it puts in the estimate (scaled coordinates of the intervals).

    Attributes
    ----------
    sigma
        FMU input -> the noise standard deviation taken from its samples.
    bias
        ``b`` per parameter (scaled coordinate: relative where log-scaled).
    error
        The Monte Carlo standard error of ``b`` per parameter (the pairs' spread / sqrt(pairs)).
    covariance
        The Monte Carlo covariance of ``b`` (to carry to combinations).
    pairs
        Antithetic pairs used.
    runs
        Twin runs (a sensitivity run counts one).
    """

    sigma: dict[str, float]
    bias: np.ndarray
    error: np.ndarray
    covariance: np.ndarray
    pairs: int
    runs: int
    first: np.ndarray = field(default_factory=lambda: np.zeros(0))
    second: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kinds: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {"sigma": self.sigma, "bias": self.bias.tolist(), "error": self.error.tolist(), "pairs": self.pairs,
                "runs": self.runs, "first_dose": self.first.tolist(), "second_dose": self.second.tolist(),
                "extrapolation": list(self.kinds)}


def _step(ev: Any, factors: np.ndarray, weights: Mapping[str, float]) -> np.ndarray:
    """The Gauss-Newton step ``-A⁺ g`` of the weighted fit at *ev* (scaled coordinates)."""
    n = factors.size
    A = np.zeros((n, n))
    g = np.zeros(n)
    res = ev.residuals()
    for tag, r in res.items():
        J = ev.jacobian[tag] * factors[None, :]
        w = float(weights[tag])
        A += w * J.T @ J
        g += w * J.T @ r
    return -np.linalg.pinv(A, rcond=1e-10) @ g


def input_bias(tw: Any, ev: Any, factors: np.ndarray, weights: Mapping[str, float], *, pairs: int = PAIRS,
               seed: int = 0, sigma: Mapping[str, float] | None = None,
               progress: Callable[[], None] | None = None) -> InputBias | None:
    """The bias of the estimate at ``ev.x`` from the measured inputs' noise (see the module).

    *tw*: the :class:`~trackingbox.identify.model.TwinWindow` of the estimate; *ev*: its evaluation with
    sensitivities at the estimate; *factors*: the scaled coordinates' factors; *weights*: the estimator's
    tag weights. *sigma*: the inputs' noise (default: :func:`input_noise` of each input's samples).
    None when no input is noisy.
    """
    window = tw.window
    if sigma is None:
        sigma = {}
        for name, u in window.inputs.items():
            u = np.asarray(u, dtype=float)
            span = float(np.ptp(u)) if u.size else 0.0
            s = input_noise(u[window.lead:])
            sigma[name] = s if s > NEGLIGIBLE * max(span, abs(float(np.mean(u))) if u.size else 0.0, 1e-300) else 0.0
    bad = [k for k in sigma if k not in window.inputs]
    if bad:
        raise EstimationError(f"inputs' noise: no input {', '.join(bad)} in the window")
    if not any(s > 0 for s in sigma.values()):
        return None
    if pairs < 1:
        raise EstimationError(f"inputs' noise: pairs must be >= 1, not {pairs}")
    rng = np.random.default_rng(seed)
    base = _step(ev, factors, weights)
    first, second = [], []
    runs = 0
    for _ in range(pairs):
        z = {k: rng.normal(0.0, 1.0, np.asarray(window.inputs[k]).size) for k, s in sigma.items() if s > 0}
        for dose, out in ((1.0, first), (2.0, second)):
            steps = []
            for sign in (1.0, -1.0):
                noisy = replace(window, inputs={k: np.asarray(u, dtype=float)
                                                + (sign * math.sqrt(dose) * sigma[k] * z[k] if k in z else 0.0)
                                                for k, u in window.inputs.items()})
                tw.window = noisy
                try:
                    e = tw.sensitivities(ev.x)
                finally:
                    tw.window = window
                runs += 1
                if progress is not None:
                    progress()
                steps.append(_step(e, factors, weights))
            out.append(0.5 * (steps[0] + steps[1]) - base)
    d1, d2 = np.asarray(first), np.asarray(second)
    bias, kinds = extrapolate(d1.mean(axis=0), d2.mean(axis=0))
    if pairs > 1:  # jackknife over the pairs
        keep = [np.arange(pairs) != i for i in range(pairs)]
        jack = np.array([extrapolate(d1[k].mean(axis=0), d2[k].mean(axis=0))[0] for k in keep])
        dev = jack - jack.mean(axis=0)
        cov = (pairs - 1) / pairs * dev.T @ dev
    else:
        cov = np.zeros((bias.size, bias.size))
    return InputBias(dict(sigma), bias, np.sqrt(np.maximum(np.diag(cov), 0.0)), cov, pairs, runs,
                     d1.mean(axis=0), d2.mean(axis=0), tuple(kinds))


def extrapolate(d1: np.ndarray, d2: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """The bias from the steps one and two more doses of the noise add (per coordinate; see the module).

    The rational extrapolant ``θ(λ) = a + β / (c + λ)`` through ``θ(0) = 0``, ``θ(1) = d1``, ``θ(2) = d2``,
    evaluated at ``λ = -1`` (no noise): the bias is ``-θ(-1)``. Exact for regression dilution
    (``θ(λ) ∝ V / (V + (1 + λ) σ²)``); ``d1`` where the doses add alike (linear). Where the extrapolant's
    pole lies in ``[-1, 0]`` (it is not to be trusted there) ``kinds`` says ``"bounds"`` and the value is
    ``d1``: :mod:`trackingbox.identify.intervals` then covers a bias from ``d1`` to ``2 d1``.

    >>> v, s2 = 2.0, 0.5  # regression dilution: θ(λ) = ln(V / (V + (1 + λ) s²)) in log coordinates, linearised
    >>> th = lambda lam: v / (v + (1 + lam) * s2) - v / (v + s2)
    >>> b, kinds = extrapolate(np.array([th(1)]), np.array([th(2)]))
    >>> round(float(b[0]), 6) == round(-th(-1), 6), kinds
    (True, ['rational'])
    """
    bias = np.array(d1, dtype=float)
    kinds = []
    for j, (x1, x2) in enumerate(zip(np.asarray(d1, float), np.asarray(d2, float))):
        den = x2 - 2.0 * x1
        if x1 == 0.0 or abs(den) <= 1e-9 * abs(x1):
            kinds.append("linear")
            continue
        c = 2.0 * (x1 - x2) / den
        if not math.isfinite(c) or c <= 1.0 or x1 * x2 <= 0:
            kinds.append("bounds")
            continue
        beta = -x1 * c * (c + 1.0)
        a = -beta / c
        bias[j] = -(a + beta / (c - 1.0))
        kinds.append("rational")
    return bias, kinds
