"""The model-error part of the tracked parameters' bands (part 7 of :mod:`.bands`).

A loop drives its own tag to the measurement whatever its parameter has to absorb: an effect the twin lacks
moves the tracked value off the plant's, and nothing on the paired tags shows it. The output tags no pair
tracks can. Were the twin's structure right, the truth ``θ*`` would make every tag agree; the loops settle
where the paired tags agree, ``G_tt (θ - θ*) = s_t`` (``s`` what the twin's structure gets wrong on a tag at
the truth), and an untracked tag ``u`` is left with the error ``e_u = s_u - G_ut (θ - θ*)``.

**What one tag says about one parameter.** Move tracked parameter ``j`` by ``Δ`` while the other loops keep
their own tags (pair ``j``'s tag let go): the other parameters follow by ``-G_kk⁻¹ G_kj Δ`` (``k`` the other
pairs) and tag ``u`` moves by ``g̃_uj Δ``, with the closed-loop gain

    ``g̃_uj = G_uj - G_uk G_kk⁻¹ G_kj``        (:func:`closed_gains`; one pair: ``G_uj``).

The value of ``p_j`` that tag ``u`` implies -- where the twin would agree with it, the other loops closing
theirs -- is ``p_j + e_u / g̃_uj``. Where the structure's error sits on pair ``j``'s own tag and tag ``u`` reads
none of it (``s`` zero but on that tag), ``θ - θ*`` lies along that same direction and the implied value is the
truth exactly: ``e_u / g̃_uj = θ*_j - p_j`` (the tests work this out on a linear twin). A tag that the missing
effect moves itself (``s_u ≠ 0``) implies a value off by ``s_u / g̃_uj``; nothing in the data tells which tag
is clean, so the band takes them all.

**The part.** For every untracked tag whose 2 h mean error ``m_u`` is beyond chance (the lack-of-fit test's
``|m_u| ≥ z s_m``, :class:`~.bands.BandTracker`; without its second condition, as large as the noise: the
part is proportional to ``m_u`` and stays small where ``m_u`` is), ``Δ_uj = m_u / g̃_uj``, carried beyond by
the mean's own 95 % margin ``1.96 s_m / |g̃_uj|``; a value no ``p_j`` within its bounds could reach (``|Δ_uj|``
more than their range) is not about ``p_j`` and is left out. The band's upper side reaches the largest
``Δ_uj`` above ``p_j``, its lower side the largest below (a structural bias, added to the side linearly as the
lag part is). Where the twin is right the means are chance, and the part is zero but in the test's false
alarms (the heat exchanger's 50 seeds: median half-width 9.50 -> 9.54).

**What one tag says about the other pairs.** A reading of pair ``k`` (the structure's error on ``k``'s own tag)
puts ``θ - θ*`` along the direction in which ``p_k`` moves while the other loops keep their tags, so it puts every
other pair's truth off as well: ``p_j`` follows ``p_k`` by ``V[j, k]`` (:func:`follows`, ``V[k, k] = 1``; the column
of ``M`` of :mod:`.bands`' part 5 divided by its diagonal entry), and the reading ``Δ_uk`` puts ``θ*_j`` at
``p_j + V[j, k] Δ_uk``. Each pair's band takes the readings of every pair carried so (*carry* of
:func:`implied_sides`; a carried value beyond ``j``'s range is left out, as one of its own), as part 5 carries
the other pairs' start, lag and hold parts. Why: on the evaporator's own plant after ``diagnose --apply`` named
the steam vent (``scripts/bench_apply --bench evaporator --cases default --seed 0``), ``pair`` put the fouling on
the product DS analyser QI-6150, which the plant's meter reads 0.002-0.0027 high (bias and drift the twin lacks):
the fouling sat 1.4-5.2e-5 m2K/W below its truth (6 h means after 12 h), its own band reached the truth through
this part (99.9 % of the rows), and ``outletValve.KvMax``, which follows the fouling 564 to one through
ZI-6150, sat 0.022-0.041 below its truth, two thirds of it carried from the fouling's miss, while its band
carried none of the fouling's model-error part (13.8 % of the rows held the truth).

**The trend.** The 2 h mean lags an error that grows: on the heat exchanger with TI-102 drifting 1.5 K over
hours (``hidden = sensor-drift``, the loop on TI-102, TI-202 clean) the implied value followed the truth 2-10
units behind, and the band held it in 44-78 % of the rows after settling, seeds 0-5. So each tag's error also
gets a second exponential mean over half the memory; the line through the two means (each at its rows' mean
age ``ℓ``) read at the newest row, ``m_now = m_W + (m_W/2 - m_W) ℓ_W / (ℓ_W - ℓ_W/2)``
(:func:`trend_weights`; ``2 m_W/2 - m_W`` once both are full), is exact on a ramp and its noise about 1.9 times
the mean's (``s_now``). It enters the part as a second reading of the same tag, tested and carried the same way
(``|m_now| ≥ z s_now``, margin ``1.96 s_now``): the band takes the mean's and the trend's implied values, each
side the farther. The half-memory is the lag part's choice (``W/2`` and ``W``), not tuned. With it the drift's
band held the truth in 90-95 % of the rows (seeds 0-5) and 94-98 % (fresh seeds 6-11); the twin right, 95.2 %
at the same median half-width, 9.54 (README, "Calibration, measured").

**What it does not cover.** An effect that moves every untracked tag as the parameter would, or none of them,
is not seen at all; nor one a tag shows only where the parameter barely moves it (``g̃_uj`` near zero, the
implied value beyond the bounds: left out). The evaporator's ``outletValve.KvMax`` is that case: its loop holds
the valve's position ZI-6150, and what the twin lacks (chiefly the boiling-point offset, as far as one bench run
tells: README) leaves the twin's product flow FI-6150 0.3-1 % below the plant's; the twin passes its smaller flow
at the measured opening with a ``KvMax`` smaller by the same share. FI-6150's error shows it, but with ZI-6150 let go the twin's level loop keeps
its flow whatever ``KvMax`` is (``g̃`` about 4e-4 per unit): nothing in the twin's response to its tracked
parameters ties that error to ``KvMax``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np


def closed_gains(gains: Any, others: Any) -> np.ndarray:
    """``g̃[u, j]``: the change of untracked tag ``u`` per unit of tracked parameter ``j`` when the other loops keep
    their own tags (module docstring).

    *gains*: ``G_tt`` (tag of pair ``i`` per unit of the parameter of pair ``j``), None with one pair;
    *others*: ``G_ut``, rows the untracked tags, a column per pair.

    >>> closed_gains(np.array([[2.0, 1.0], [1.0, 4.0]]), np.array([[1.0, 2.0]]))
    array([[0.5, 1.5]])
    """
    g_ut = np.atleast_2d(np.asarray(others, dtype=float))
    if gains is None:
        if g_ut.shape[1] != 1:
            raise ValueError(f"closed-loop gains of {g_ut.shape[1]} pairs need the loops' gain matrix")
        return g_ut.copy()
    g_tt = np.asarray(gains, dtype=float)
    n = g_tt.shape[0]
    if g_tt.shape != (n, n) or g_ut.shape[1] != n:
        raise ValueError(f"the loops' gain matrix {g_tt.shape} and the untracked tags' gains {g_ut.shape} "
                         "do not match (one column per pair)")
    out = np.empty_like(g_ut)
    for j in range(n):
        k = [i for i in range(n) if i != j]
        follow = np.linalg.solve(g_tt[np.ix_(k, k)], g_tt[k, j]) if k else np.zeros(0)
        out[:, j] = g_ut[:, j] - g_ut[:, k] @ follow
    return out


def follows(gains: Any) -> np.ndarray:
    """``V[j, k]``: how far tracked parameter ``j`` moves per unit of pair ``k``'s parameter while the other loops
    keep their own tags (``V[k, k] = 1``; module docstring). *gains*: ``G_tt`` as :func:`closed_gains` takes it.

    >>> follows(np.array([[2.0, 1.0], [1.0, 4.0]]))
    array([[ 1.  , -0.5 ],
           [-0.25,  1.  ]])
    """
    g_tt = np.asarray(gains, dtype=float)
    n = g_tt.shape[0]
    out = np.eye(n)
    for j in range(n):
        k = [i for i in range(n) if i != j]
        if k:
            out[k, j] = -np.linalg.solve(g_tt[np.ix_(k, k)], g_tt[k, j])
    return out


def implied_sides(means: Sequence[float], flagged: Sequence[bool], closed: Any,
                  spans: Sequence[float], margins: Sequence[float] | None = None,
                  carry: Any = None) -> list[tuple[float, float]]:
    """Per pair, the model-error part's (below, above) extent about the tracked value (module docstring).

    *means*: each untracked tag's mean error (measured - tracked); *flagged*: whether the lack-of-fit test flags
    it; *closed*: :func:`closed_gains` (rows the tags, in the same order); *spans*: each pair's bounds' range;
    *margins*: each mean's own uncertainty (its 95 % half-width), carried through the gain beyond the value;
    *carry*: :func:`follows` (None: each pair its own readings alone).

    >>> implied_sides([0.75, -1.0, 5.0], [True, True, False], np.array([[0.25], [0.5], [1.0]]), [10.0])
    [(2.0, 3.0)]
    """
    g = np.atleast_2d(np.asarray(closed, dtype=float))
    n = len(spans)
    v = np.eye(n) if carry is None else np.asarray(carry, dtype=float)
    below, above = [0.0] * n, [0.0] * n
    for m, flag, row, margin in zip(means, flagged, g, margins if margins is not None else [0.0] * len(g)):
        for k in range(n):
            gain = float(row[k])
            if not (flag and math.isfinite(m) and math.isfinite(gain) and gain != 0.0):
                continue
            d = m / gain
            if abs(d) > spans[k]:
                continue  # no value within the bounds explains it: not this parameter's
            for j in range(n):
                c = float(v[j, k])
                if c == 0.0 or not math.isfinite(c) or abs(c * d) > spans[j]:
                    continue  # the reading puts p_j beyond its bounds' range: not about it
                dj = c * d if c != 1.0 else d
                dj += math.copysign(abs(c) * margin / abs(gain), dj)
                below[j], above[j] = max(below[j], -dj), max(above[j], dj)
    return list(zip(below, above))


def trend_weights(lam_short: float, lam_long: float, n: int) -> tuple[float, float]:
    """``(a, v)`` of the trend reading (module docstring): ``m_now = a m_short + (1 - a) m_long`` of two exponential
    means filled from zero over the last *n* rows (forgetting factors *lam_short* < *lam_long*, each mean divided
    by its weight), and its variance per unit of the error's long-run variance, ``Σ c_i²`` with ``c_i`` the rows'
    weights in ``m_now`` (rows taken as white at that level, as the mean's own ``s_m`` does). ``a`` puts the
    line through both means at the newest row: exact on a ramp. (NaN, NaN) with under two rows.

    >>> [round(x, 6) for x in trend_weights(0.25, 0.5, 2)]   # two rows: the newest alone
    [2.5, 1.0]
    """
    if n < 2 or not (0.0 < lam_short < lam_long < 1.0):
        return math.nan, math.nan

    def sums(lam: float) -> tuple[float, float, float]:  # Σ λ^i, Σ i λ^i, Σ λ^2i over i < n
        q = lam ** n
        return ((1.0 - q) / (1.0 - lam), lam * (1.0 - n * lam ** (n - 1) + (n - 1) * q) / (1.0 - lam) ** 2,
                (1.0 - q * q) / (1.0 - lam * lam))

    (ws, ks, ss), (wl, kl, sl) = sums(lam_short), sums(lam_long)
    age_s, age_l = ks / ws, kl / wl
    a = age_l / (age_l - age_s)
    x = lam_short * lam_long
    cross = (1.0 - x ** n) / (1.0 - x) / (ws * wl)
    return a, a * a * ss / (ws * ws) + (1.0 - a) ** 2 * sl / (wl * wl) + 2.0 * a * (1.0 - a) * cross


def trend_reading(short: Sequence[float], mean: float, n: int, lams: tuple[float, float], lrv: float,
                  z_test: float, z: float) -> tuple[float, bool, float]:
    """One tag's trend reading ``(m_now, beyond chance, margin)`` (module docstring): *short* the half-memory mean's
    (weight, weighted value), *mean* the full memory's mean, *n* the rows in both, *lams* their forgetting factors,
    *lrv* the error's long-run variance; beyond chance at ``|m_now| ≥ z_test s_now``, margin ``z s_now``.

    >>> now, beyond, margin = trend_reading((0.75, 1.5), 1.0, 2, (0.25, 0.5), 4.0, 3.0, 2.0)  # 2.5 · 2 - 1.5 · 1
    >>> round(now, 9), beyond, round(margin, 9)                                            # s_now 2
    (3.5, False, 4.0)
    """
    a, v = trend_weights(lams[0], lams[1], n) if short[0] > 0 else (math.nan, math.nan)
    if not (math.isfinite(a) and math.isfinite(mean)):
        return math.nan, False, 0.0
    now, s_now = a * short[1] / short[0] + (1.0 - a) * mean, math.sqrt(lrv * v)
    return now, abs(now) >= z_test * s_now, z * s_now
