"""The sign changes of the PI rate within a sample (linear error), against scipy.

``_integrate_clamped_linear`` cuts a sample where the rate
``g(t) = A + B·t + k·exp(-t/te)`` of ``ParameterController`` changes sign and
clamps after each piece. The zeros must be those of ``scipy.optimize.brentq`` on
the same ``g``, and the clamped end value that of ``scipy.integrate.solve_ivp``
on the block's law (``u`` and the error memory ``m`` integrated together, the
clamp as conditional integration), for zeros near either end of the sample and
an extremum inside it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from trackingbox.tracking.controllers import _integrate_clamped_linear, _zero_of_rate


def _law_from_zeros(z1: float, z2: float, k: float, te: float, ti: float, ts: float) -> tuple[float, float, float]:
    """``(e0, e1, m0)`` whose rate over a sample of *ts* s is zero at *z1* and *z2* (s), with ``g'' ~ k``.

    ``g(t) = A + B·t + k·exp(-t/te)`` through both zeros gives ``A`` and ``B``;
    the block's variables follow from ``B = s/ti``, ``A = e0/ti + s`` and
    ``k = (e0 - m0 - s·te)/te`` with ``s = (e1 - e0)/ts``.
    """
    q1, q2 = -k * math.exp(-z1 / te), -k * math.exp(-z2 / te)
    b = (q2 - q1) / (z2 - z1)
    a = q1 - b * z1
    s = b * ti
    e0 = (a - s) * ti
    return e0, e0 + s * ts, e0 - s * te - k * te


def _rate(e0: float, e1: float, m0: float, ti: float, ts: float, te: float):
    s = (e1 - e0) / ts
    a, b, k = e0 / ti + s, s / ti, (e0 - m0 - s * te) / te
    return (lambda t: a + b * t + k * math.exp(-t / te)), (a, b, k)


# (zero 1, zero 2) as fractions of the sample; te and ti as in the runtime (te = ts/10) or slower
CASES = [
    (1e-7, 0.5, 0.1, 3.0),       # a zero just after the start, the second mid-sample
    (0.3, 1.0 - 1e-7, 0.1, 3.0),  # a zero just before the end
    (0.02, 0.98, 0.1, 40.0),      # both near the ends, the extremum inside
    (0.2, 0.25, 0.5, 1.0),        # two close zeros around the extremum
    (1e-4, 0.9999, 0.05, 200.0),
]


@pytest.mark.parametrize("f1, f2, te_frac, ti", CASES)
@pytest.mark.parametrize("k", [2.0, -0.7])
def test_zeros_are_brentq_zeros(f1: float, f2: float, te_frac: float, ti: float, k: float) -> None:
    ts = 10.0
    te = te_frac * ts
    e0, e1, m0 = _law_from_zeros(f1 * ts, f2 * ts, k, te, ti, ts)
    g, (a, b, kk) = _rate(e0, e1, m0, ti, ts, te)
    t_ext = -te * math.log(b * te / kk)  # where g' = 0: the pieces on which g is monotone
    assert 0.0 < t_ext < ts
    for lo, hi in ((0.0, t_ext), (t_ext, ts)):
        assert g(lo) * g(hi) < 0.0
        ref = brentq(g, lo, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)
        got = _zero_of_rate(a, b, kk, te, lo, hi, g(lo))
        assert lo < got < hi
        assert got == pytest.approx(ref, rel=1e-12, abs=1e-13 * ts)


def test_zeros_on_random_monotone_pieces() -> None:
    rng = np.random.default_rng(12)
    checked = 0
    for _ in range(400):
        ts = float(rng.choice([1.0, 10.0, 60.0]))
        te = ts * float(rng.choice([0.05, 0.1, 1.0]))
        ti = float(10 ** rng.uniform(0.0, 3.0))
        e0 = float(rng.normal(0.0, 5.0))
        e1 = float(e0 + rng.normal(0.0, 3.0))
        m0 = float(e0 + rng.normal(0.0, 3.0))
        g, (a, b, k) = _rate(e0, e1, m0, ti, ts, te)
        points = [0.0, ts]
        r = b * te / k if k else -1.0
        if 0.0 < r < 1.0 and 0.0 < -te * math.log(r) < ts:
            points.insert(1, -te * math.log(r))
        for lo, hi in zip(points[:-1], points[1:]):
            if g(lo) * g(hi) < 0.0:
                ref = brentq(g, lo, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)
                assert _zero_of_rate(a, b, k, te, lo, hi, g(lo)) == pytest.approx(ref, rel=1e-12, abs=1e-13 * ts)
                checked += 1
    assert checked > 50  # the draw has zeros to check


def _clamped_by_solve_ivp(u0: float, gain: float, ti: float, e0: float, e1: float, m0: float, ts: float,
                          te: float) -> float:
    """The block's law over one sample, ``u`` and the memory ``m`` integrated together by scipy."""
    def rhs(t: float, y: np.ndarray) -> list[float]:
        u, m = y
        e = e0 + (e1 - e0) * t / ts
        rate = gain * (e / ti + (e - m) / te)
        if (u >= 100.0 and rate > 0.0) or (u <= 0.0 and rate < 0.0):
            rate = 0.0
        return [rate, (e - m) / te]

    sol = solve_ivp(rhs, (0.0, ts), [u0, m0], method="RK45", rtol=1e-10, atol=1e-10, max_step=ts / 1000)
    assert sol.success
    return float(np.clip(sol.y[0, -1], 0.0, 100.0))


@pytest.mark.parametrize("f1, f2, te_frac, ti", CASES[:4])
@pytest.mark.parametrize("k, u0", [(20.0, 99.0), (20.0, 1.0), (-15.0, 0.5), (-15.0, 99.5), (20.0, 50.0)])
def test_clamped_end_value_matches_solve_ivp(f1: float, f2: float, te_frac: float, ti: float, k: float,
                                             u0: float) -> None:
    ts, gain = 10.0, 1.5
    te = te_frac * ts
    e0, e1, m0 = _law_from_zeros(f1 * ts, f2 * ts, k, te, ti, ts)
    ref = _clamped_by_solve_ivp(u0, gain, ti, e0, e1, m0, ts, te)
    assert _integrate_clamped_linear(u0, gain, ti, e0, e1, m0, ts, te) == pytest.approx(ref, abs=1e-6)


def test_clamp_takes_effect_in_these_cases() -> None:
    # the solve_ivp comparison above means something only if a bound is reached before the rate turns:
    # then the clamped answer differs from clamping the unclamped end value u0 + F(ts)
    ts, gain = 10.0, 1.5
    differ = 0
    for f1, f2, te_frac, ti in CASES[:4]:
        for k, u0 in [(20.0, 99.0), (20.0, 1.0), (-15.0, 0.5), (-15.0, 99.5), (20.0, 50.0)]:
            te = te_frac * ts
            e0, e1, m0 = _law_from_zeros(f1 * ts, f2 * ts, k, te, ti, ts)
            s = (e1 - e0) / ts
            c = e0 - m0 - s * te
            free = u0 + gain * ((e0 / ti + s) * ts + 0.5 * s / ti * ts * ts + c * (1.0 - math.exp(-ts / te)))
            clamped = _integrate_clamped_linear(u0, gain, ti, e0, e1, m0, ts, te)
            differ += abs(clamped - min(max(free, 0.0), 100.0)) > 0.1
    assert differ >= 4  # of the 20 cases
