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

**What it does not cover.** The 2 h mean lags an error that grows: on the heat exchanger with TI-102 drifting
1.5 K over hours (``hidden = sensor-drift``, the loop on TI-102, TI-202 clean) the implied value followed the
truth 2-10 units behind, and the band held it in 44-78 % of the rows after settling (0.2-1.1 % without the
part), seeds 0-5. An effect that moves every untracked tag as the parameter would, or none of them, is not
seen at all.
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


def implied_sides(means: Sequence[float], flagged: Sequence[bool], closed: Any,
                  spans: Sequence[float], margins: Sequence[float] | None = None) -> list[tuple[float, float]]:
    """Per pair, the model-error part's (below, above) extent about the tracked value (module docstring).

    *means*: each untracked tag's mean error (measured - tracked); *flagged*: whether the lack-of-fit test flags
    it; *closed*: :func:`closed_gains` (rows the tags, in the same order); *spans*: each pair's bounds' range;
    *margins*: each mean's own uncertainty (its 95 % half-width), carried through the gain beyond the value.

    >>> implied_sides([0.75, -1.0, 5.0], [True, True, False], np.array([[0.25], [0.5], [1.0]]), [10.0])
    [(2.0, 3.0)]
    """
    g = np.atleast_2d(np.asarray(closed, dtype=float))
    out = []
    for j, span in enumerate(spans):
        below = above = 0.0
        for m, flag, row, margin in zip(means, flagged, g, margins if margins is not None else [0.0] * len(g)):
            gain = float(row[j])
            if not (flag and math.isfinite(m) and math.isfinite(gain) and gain != 0.0):
                continue
            d = m / gain
            if abs(d) > span:
                continue  # no value within the bounds explains it: not this parameter's
            d += math.copysign(margin / abs(gain), d)
            below, above = max(below, -d), max(above, d)
        out.append((below, above))
    return out
