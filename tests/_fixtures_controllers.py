"""The PI law's sample cases and a scipy reference of the clamped law (shared by the controller tests).

``law_from_zeros`` builds the block's variables whose rate has two given zeros within a
sample; ``clamped_by_solve_ivp`` integrates the block's law over one sample with scipy (the
independent reference of ``_integrate_clamped_linear`` and of the rows in C).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp


def law_from_zeros(z1: float, z2: float, k: float, te: float, ti: float, ts: float) -> tuple[float, float, float]:
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


# (zero 1, zero 2) as fractions of the sample; te and ti as in the runtime (te = ts/10) or slower
CASES = [
    (1e-7, 0.5, 0.1, 3.0),       # a zero just after the start, the second mid-sample
    (0.3, 1.0 - 1e-7, 0.1, 3.0),  # a zero just before the end
    (0.02, 0.98, 0.1, 40.0),      # both near the ends, the extremum inside
    (0.2, 0.25, 0.5, 1.0),        # two close zeros around the extremum
    (1e-4, 0.9999, 0.05, 200.0),
]


def clamped_by_solve_ivp(u0: float, gain: float, ti: float, e0: float, e1: float, m0: float, ts: float,
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
