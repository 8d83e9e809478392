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

**The bias** to first order in the noise variance (:func:`input_bias`) is what
one more dose of the same noise does to the estimate: ``K`` antithetic pairs
``u ± δ_k`` (``δ_k`` white with the estimated ``σ`` per input), each run with
the sensitivities at the estimate, each giving the Gauss-Newton step of its
own fit, ``Δz = -A_k⁺ g_k`` (``g_k = Σ_tag w_tag J_kᵀ r_k`` in the scaled
coordinates of the intervals). In the pair's mean the part linear in ``δ``
cancels exactly; what is left, averaged over the pairs and less the step at the
measured inputs, is ``b``: the bias that a second dose of the noise adds.

**Why ``b`` is a lower bound.** Where a parameter sets how much noise the twin
passes on, the noise's own share of the cost bends it too (a filter's passed
variance goes as ``1/τ``: its slope in ``ln τ`` falls as ``τ`` grows), so the bias
saturates with the noise: the second dose adds less than the first put in. On the
heat-exchanger bench with the hot side's volume estimated (``hx2`` of
``scripts/bench_uncertainty``) ``b`` was 0.47-0.59 of the estimate's actual error
in ``ln V1`` on 4 seeds (0, 4, 11, 19), and a fixed point ``θ = θ̂ - b(θ)`` did not
close the gap (``b`` is smaller at the lower volume). :mod:`trackingbox.identify.intervals`
therefore moves the interval so that it covers a bias from ``b`` to ``2b`` (the
estimate is biased by ``b`` or more, and by no more than twice ``b`` on that bench --
an assumption measured there, not a theorem), and widens it by the pairs' spread
(the correction's own Monte Carlo error).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
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

    def to_json(self) -> dict[str, Any]:
        return {"sigma": self.sigma, "bias": self.bias.tolist(), "error": self.error.tolist(), "pairs": self.pairs,
                "runs": self.runs}


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
    means = []
    runs = 0
    for _ in range(pairs):
        delta = {k: rng.normal(0.0, s, np.asarray(window.inputs[k]).size) for k, s in sigma.items() if s > 0}
        steps = []
        for sign in (1.0, -1.0):
            noisy = replace(window, inputs={k: np.asarray(u, dtype=float) + sign * delta[k] if k in delta else u
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
        means.append(0.5 * (steps[0] + steps[1]) - base)
    m = np.asarray(means)
    bias = m.mean(axis=0)
    cov = np.cov(m.T, ddof=1).reshape(bias.size, bias.size) / pairs if pairs > 1 else np.zeros((bias.size,) * 2)
    return InputBias(dict(sigma), bias, np.sqrt(np.maximum(np.diag(cov), 0.0)), cov, pairs, runs)
