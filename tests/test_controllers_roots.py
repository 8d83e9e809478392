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
from scipy.optimize import brentq

from _fixtures_controllers import CASES, clamped_by_solve_ivp, law_from_zeros
from trackingbox.tracking.controllers import _integrate_clamped_linear, _zero_of_rate


def _rate(e0: float, e1: float, m0: float, ti: float, ts: float, te: float):
    s = (e1 - e0) / ts
    a, b, k = e0 / ti + s, s / ti, (e0 - m0 - s * te) / te
    return (lambda t: a + b * t + k * math.exp(-t / te)), (a, b, k)


@pytest.mark.parametrize("f1, f2, te_frac, ti", CASES)
@pytest.mark.parametrize("k", [2.0, -0.7])
def test_zeros_are_brentq_zeros(f1: float, f2: float, te_frac: float, ti: float, k: float) -> None:
    ts = 10.0
    te = te_frac * ts
    e0, e1, m0 = law_from_zeros(f1 * ts, f2 * ts, k, te, ti, ts)
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


@pytest.mark.parametrize("f1, f2, te_frac, ti", CASES[:4])
@pytest.mark.parametrize("k, u0", [(20.0, 99.0), (20.0, 1.0), (-15.0, 0.5), (-15.0, 99.5), (20.0, 50.0)])
def test_clamped_end_value_matches_solve_ivp(f1: float, f2: float, te_frac: float, ti: float, k: float,
                                             u0: float) -> None:
    ts, gain = 10.0, 1.5
    te = te_frac * ts
    e0, e1, m0 = law_from_zeros(f1 * ts, f2 * ts, k, te, ti, ts)
    ref = clamped_by_solve_ivp(u0, gain, ti, e0, e1, m0, ts, te)
    assert _integrate_clamped_linear(u0, gain, ti, e0, e1, m0, ts, te) == pytest.approx(ref, abs=1e-6)


def test_clamp_takes_effect_in_these_cases() -> None:
    # the solve_ivp comparison above means something only if a bound is reached before the rate turns:
    # then the clamped answer differs from clamping the unclamped end value u0 + F(ts)
    ts, gain = 10.0, 1.5
    differ = 0
    for f1, f2, te_frac, ti in CASES[:4]:
        for k, u0 in [(20.0, 99.0), (20.0, 1.0), (-15.0, 0.5), (-15.0, 99.5), (20.0, 50.0)]:
            te = te_frac * ts
            e0, e1, m0 = law_from_zeros(f1 * ts, f2 * ts, k, te, ti, ts)
            s = (e1 - e0) / ts
            c = e0 - m0 - s * te
            free = u0 + gain * ((e0 / ti + s) * ts + 0.5 * s / ti * ts * ts + c * (1.0 - math.exp(-ts / te)))
            clamped = _integrate_clamped_linear(u0, gain, ti, e0, e1, m0, ts, te)
            differ += abs(clamped - min(max(free, 0.0), 100.0)) > 0.1
    assert differ >= 4  # of the 20 cases
