"""Uncertainty bands on tracked parameters, row by row, from what the tracking loop itself sees.

A parameter controller is a filter from its tag's measurement to the parameter:
the tag's noise moves the parameter, and a change of the plant's true value
reaches it only through the loop's dynamics. For each ``[[pairs]]`` entry
:func:`loop_model` linearises the loop the tracking runtime runs -- the
pair's first-order step response (``gain``, ``time_constant``, the parameter
held over a sample) closed by its PI law (:func:`trackingbox.tracking.tuning.pair_settings`:
``Δp = Kc (Δe + Ts (e_k + e_k-1) / (2 Ti))``) -- and computes

* ``h``: the parameter's response to a unit impulse of measurement noise, and
* ``d``: what is left of an initial parameter error after ``k`` samples in auto
  (1 at the start), with ``T_lag = Ts Σ d`` the loop's lag behind a ramp.

:class:`BandTracker` then gives every CSV row a band ``[lo, hi]`` around the
tracked value ``p`` (level :data:`LEVEL`), in seven parts:

1. **noise**: ``z σ_n`` with ``σ_n² = Σ_l γ(l) R_h(l)`` -- ``γ`` the
   autocovariance of the tag's fast error (tracked error minus its centred
   30 min mean, as pairing's noise floor; forgotten over :data:`NOISE_MEMORY`,
   from auto rows only), ``R_h`` the autocorrelation of ``h``; the band is
   empty until :data:`NOISE_MIN` of fast error has been seen;
2. **start**: the truth lies in the start's interval ``[a, b]`` (the spec's
   ``interval`` of the parameter, which ``estimate --write`` records, else its
   bounds), so after ``k`` auto samples ``p* ∈ [p - (p0 - a)|d_k|, p + (b - p0)|d_k|]``
   (sides swapped where ``d_k < 0``), combined with the noise part in quadrature;
3. **lag**: a truth moving at rate ``ρ`` is ``ρ T_lag`` ahead of ``p``; ``ρ`` is
   the tracked value's own slope over a day (:data:`RATE_MEMORY`, at least ``T_lag``:
   two exponential means of the auto rows' ``p`` over half of it and all of it, each
   with its rows' mean time, ``ρ = ΔP/Δt``, exact on a ramp however short the history),
   added on the side it moves to; while the controller holds (stoppage, missing tag)
   the truth may move on: the rate before the hold times its length is added there,
   and fades with ``d`` once tracking resumes.

   Why a day and not ``T_lag``: a slow error on a tag makes the loops wander, and the
   wander's slope over ``T_lag`` is as large as a slow truth's rate. On the evaporator's
   twin-structure plant the fouling's rate over its 3 h lag was twice the truth's in the median
   and of the wrong sign in 11 % of the rows (``scripts/explain_evaporator_bands``, seed 0):
   ``outletValve.KvMax``'s truth sat above ``p`` by 0.004-0.010 on average after 12 h (seeds
   0-2), of which the fouling's motion behind the loops gave 0.007-0.009 (the linearised loops
   driven by the truth's motion alone), and in 8 of the 12 3 h windows where its band held the
   truth in under 90 % of the rows, that rate, carried 560 to one (part 5), put less on the band
   than the motion put on the truth (0.0002-0.0068 against 0.0023-0.0106), the paired tags' slow
   errors at the truth adding up to 0.008 (QI-6150) and 0.010 (ZI-6150) on top. Over a day the
   carried lag was 0.0059-0.0124 in those windows; seeds 0-2 (``--rebands``): 84.9, 85.3, 97.1 %
   -> 91.9, 95.1, 97.2 %, median half-width 0.0160, 0.0169, 0.0134 -> 0.0162, 0.0165, 0.0139. The
   cost: a rate that changes within hours (a cleaning) reaches the lag part over a day.
4. **fixed**: a parameter the twin holds at an estimate (``[fixed]`` after ``estimate``, or a
   ``[[parameters]]`` entry no pair tracks) is off by up to its interval, and the loop makes
   its own parameter absorb that: where the pair's tag moves by ``Δy(q)`` when the held ``q``
   goes from its estimate to an end of its interval, the truth lies ``-Δy(q)/gain`` from ``p``
   (with several pairs the loops absorb it together: ``-G⁻¹ Δy(q)`` over the paired tags, ``G``
   the tracked parameters' gains on them, :func:`trackingbox.identify.held.joint_shifts`)
   (a steady shift: the held value never moves, so this part does not fade). Given per pair
   as :class:`Fixed` (*fixed* of :class:`BandTracker`): the shifts of the truth at the two ends
   of each held parameter's interval; each side takes the shifts toward it, in quadrature
   over the fixed parameters and with the noise and start parts. The shifts need the tag's
   sensitivity to the held parameters, which the twin alone gives: ``track`` (and the online
   mode, and ``diagnose --apply``'s re-track) measures it at its start by step tests on the twin
   (:func:`trackingbox.identify.held.band_parts`) for every held parameter with an interval
   (``[fixed_intervals]``, or ``interval`` of an untracked ``[[parameters]]`` entry);
   ``scripts/bench_apply --explain-bands`` replays the whole record instead.

   Why: on the evaporator (``diagnose --apply``, vent-orifice, 72 h) the patched twin holds
   the named vent's fraction at 0.0144 (interval 0.0120..0.0163). Replayed with the fouling
   forced to the plant's, the twin reads PI-6121 137 Pa lower with the fraction at the
   interval's upper end: 1.4e-5 m2K/W of fouling, 2.5 times the band's median half-width
   without this part, and the size of the misses (from 48 h on the truth sat about 1e-5 above
   ``p`` and the band's upper side 5e-6 above it, while the loop's own error read 0 +- 30 Pa;
   ``scripts/bench_apply --explain-bands``).
5. **interaction**: with several pairs, every loop drives its own tag to the measurement
   together with the others, so a tracked parameter also absorbs what the other tracked
   parameters' errors do to its tag: with ``G`` the tracked parameters' steady gains on the
   paired tags (tag ``i`` of pair ``i`` per unit of parameter ``j``), the slow errors ``e`` the
   loops are left with put the truths ``G⁻¹ e`` from the tracked values, where each pair's band
   alone takes ``e_k/G_kk``. So pair ``j``'s band carries pair ``k``'s start, lag and hold parts
   scaled by ``M[j, k]``, ``M = G⁻¹ diag(G)`` (``G``: *gains* of :class:`BandTracker`; a negative
   entry turns ``k``'s sides over): the squared start parts summed, the lag and hold parts
   added. ``M`` is the identity when the loops do not interact (and the band is the one above).
   ``M`` is the steady state's, and the noise moves the loops faster than they reach it:
   carried through ``M``, 0.3 of noise on the other tag of a 2x2 linear twin made a band 28 of its
   parameter's standard deviations wide (median). So the noise part is the loops' together instead
   (:func:`loops_noise`): every tag follows all the parameters through ``G`` with its own pair's
   lag, each parameter its own PI law, and pair ``j``'s noise variance sums each tag's fast
   error through the impulse response from that tag to ``j`` (on that twin: the band held the
   truth in 95.9 % of the rows where its own loop's noise alone gave 80.1 %; where the loops
   together do not settle, each pair's own noise part). The fixed part is
   already the loops' joint shift (part 4) and is not carried again. ``track`` measures ``G`` with the
   fixed part's step tests (:func:`trackingbox.identify.held.band_parts`), one pair needs none.

   Why: the evaporator's twin pairs three loops, and the fouling moves the outlet valve's
   ZI-6150 as well as its own tag (``G`` 36.8 per m2K/W against the valve's own -0.064 per unit
   of ``outletValve.KvMax``): the valve's ``KvMax`` absorbs what the fouling's error does to its
   tag. On the twin-structure plant (``scripts/bench_uncertainty --cases bands-evaporator-plain
   --rebands``, seeds 0-2) its band held the truth in 36.6 % of the rows after 12 h from its own
   loop alone, 75.9 % with this part. What is left are the fouling's slow errors (6 h means up to
   3.5e-5, carried 560 to one), which its own band holds through a noise part dominated by the
   controller's fast kick, which the valve's loop does not pass on. Where they come from
   (``scripts/explain_evaporator_bands``, seeds 0-2): the three loops linearised as here, driven by
   what the twin reads wrong at the truth on each paired tag and by the fouling's motion, reproduce
   the misses (correlation 0.97-0.99; the valve's rms 0.0065-0.0117), and the valve's come in
   comparable shares from (i) the fouling's motion behind the loops' lag and holds (rms 0.009-0.011
   on ``KvMax``), (ii) QI-6150's own error at the truth (the analyser's noise as the historian
   records it; not the inputs: with the plant's true inputs the sd of its 6 h means goes from
   1.9-2.1e-4 to 1.6-2.0e-4), which the fouling's loop integrates into a wander that reaches the
   valve through ZI-6150 (rms 0.005-0.0064 against this part's 0.0011 from that tag), and (iii)
   ZI-6150's error at the truth, most of it from the levels' state compensation (the sd of its 6 h
   means 2.3-2.9e-4 with it, 0.9e-4 without), with mostly 2-20 times the fast error's spectral level
   at periods of 9-45 h (one of 15 estimates below 1; rms 0.0046-0.0055 against 0.0020). The noise
   part takes the fast error's level (30 lags of the error less its 30 min mean) to hold at the
   loops' periods; a parameter the noise reaches only through the loops' slow path, as the valve's, is fed
   by exactly the periods where that fails, and a 72 h record does not pin down a spectrum at them.
6. **slow**: the paired tags' errors at the loops' own time scale, beyond what their fast error's
   level puts there. The rows' tracked errors (every paired tag, auto rows only, from the row where
   each pair's start has faded below :data:`SLOW_START` of itself) are averaged over batches of ``N``
   samples, ``N Ts`` the slowest pair's ``T_lag``; ``C`` is the batch means' covariance across the
   tags (forgotten over :data:`SLOW_MEMORY`, none before :data:`SLOW_MIN` batches) less, on its
   diagonal, what the tag's fast error alone gives a batch mean (its tapered ``Σ γ`` over ``N``).
   Taken as errors of covariance ``C (1 - |l|/N)`` at lag ``l`` (a spectrum of level ``N C`` below
   the batch's frequency), they give pair ``j`` the variance ``Σ_kq C[k, q] w[j, k, q]``
   (:func:`batch_weights`, through the loops' joint impulse responses of part 5, or each pair's own
   loop without gains), added to the noise part's. A hold or a gap drops the batch under way.

   What it sees and what it cannot: the loop drives its own tag's slow error into the parameter, so
   the tracked error keeps only what the loop has not yet absorbed (the sensitivity ``1/(1 + GC)``).
   A tag error reaching a parameter through another loop, as QI-6150's and ZI-6150's reach the
   valve's ``KvMax`` on the evaporator, shows in the batch means the loops are left with; an error
   on a loop's own tag slower than the loop hides from it, and from any statistic of that tag alone
   (the tracker cannot tell it from a change of the parameter it tracks). The fast level is subtracted as
   it shows through the loops (a white error of level ``L`` on tag ``q`` puts ``L s_iq ⋆ s_kq`` into the
   batch means, ``s`` the tracked errors' impulse responses), and only the excess beyond
   :data:`SLOW_SIGNIFICANCE` times the estimate's own relative scatter ``sqrt(2 Σλ^2i) / Σλ^i`` counts; a
   loop whose lag is inside the fast error's 30 min window gets no slow part (the noise part measures that
   time scale; on a faster one the fast level is itself attenuated by the loop, and the excess is spurious).
   Measured on the runtime's loop of ``tests/test_identify_bands.py`` with a lag of about an hour: white
   noise alone, the band unchanged; with an AR(1) analyser error of the same size and a 30 min
   correlation time, the band held the truth in 84.9 % of the rows, 70.9 % without this part. On the
   evaporator's twin-structure plant (``scripts/bench_uncertainty --cases bands-evaporator-plain
   --evaporator-seeds 3 --rebands``, all three lags 3.0 h) ``KvMax``'s band held the truth in 84.9, 85.2
   and 97.1 % of the rows after 12 h (72.0, 72.1, 83.5 % without it), its median half-width 0.0160 (0.0115);
   the misses are from 24 h on (seeds 0-1: 97-100 % in 12-24 h, 77 % in 24-48 h), where the fouling's motion and
   the loops' own-tag errors are the part no batch mean of tracked error shows (the first is the lag part's: 3).
7. **model error**: where an untracked tag's mean error, or its trend read at the newest row, is beyond chance
   (the lack-of-fit test's first condition, below), the value of ``p`` it implies, the other loops keeping their
   tags (:mod:`.misfit`): the side toward it reaches it (*misfit* of :class:`BandTracker`, the closed-loop gains);
   with several pairs, also what each other pair's reading puts on this one (``V = follows(G)``, :mod:`.misfit`).

The band is clipped to the parameter's bounds. ``result.json``'s band summary
names, per tracked parameter, what it takes as exact (``taken_as_exact``: the
twin's ``[fixed]`` values and the parameters no pair tracks, less those given a
fixed part). What the twin's structure gets wrong (an effect the twin lacks, absorbed by the
parameter) no loop can see from its own tag, which it drives to the measurement whatever the parameter
has to absorb; part 7 takes it from the tags no loop drives, as far as they show it.

**Lack of fit: where the band is not to be trusted.** The other measured tags
can see it. For every output tag no pair tracks, :class:`BandTracker` keeps the
same fast-error statistics as for a pair's tag (its fast noise ``γ``, standard
deviation ``σ = sqrt(γ(0))``) and an exponential mean ``m`` of its error over
:data:`FIT_MEMORY`; were the twin right, ``m`` would be noise, of standard
deviation ``s_m = sqrt((1-λ)/(1+λ) · Σ_l γ(l))`` (``λ = exp(-Ts/FIT_MEMORY)``,
the same tapered lags). A tag disagrees when ``|m|`` is both beyond chance
(``|m| ≥ z s_m``, ``z`` a two-sided Bonferroni quantile over the tags at
:data:`FIT_ALPHA`) and as large as the noise itself (``|m| ≥ FIT_EFFECT σ``: a
twin off by a hundredth of its noise is significant over days, and harmless).
The CSV's ``lack_of_fit`` column is ``max_tag min(|m| / (z s_m), |m| / (FIT_EFFECT σ))``:
**at 1 or more a tag the loops do not touch disagrees with the twin beyond its
noise, and the bands do not cover that model error** (NaN until an hour of fast
error and one :data:`FIT_MEMORY` are seen; no column without such tags).
``result.json``'s band summary names the tags and the share of rows flagged.
It says *that* the twin is off; part 7 reads each flagged tag's offset as a value of
the parameter, which can disagree from tag to tag (an effect the twin lacks acting on
a tag directly): the band takes them all; finding the missing effect is diagnosis's work. ``FIT_EFFECT = 1`` was
chosen after one seed of the evaporator bench with and without the effects its
twin lacks (untracked tags' 2 h mean errors at most 0.53 σ in 90 % of the rows
without them, one at 2.6 σ in half of the rows with them).

Everything is causal and its state small (:meth:`BandTracker.state_dict`), so
the online mode publishes the same band as an offline run writes, and a resumed
run writes the same bytes.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import norm

from ..analysis.offsets import FLOOR_SPAN
from ..errors import CheckpointError
from ..tracking.tuning import pair_settings
from .misfit import follows, implied_sides, trend_reading

#: Confidence level of the bands.
LEVEL = 0.95
#: Forgetting time (s) of the noise statistics.
NOISE_MEMORY = 12 * 3600.0
#: Fast error (s, in auto) seen before the band is given.
NOISE_MIN = 3600.0
#: Lags (samples) of the fast error's autocovariance used.
NOISE_LAGS = 30
#: The impulse and decay responses are followed for this many loop lag times.
HORIZON = 12.0
#: Forgetting time (s) of the slow part's batch means (part 6 of the module).
SLOW_MEMORY = 24 * 3600.0
#: Memory (s) of the lag part's rate, the tracked value's slope (part 3 of the module).
RATE_MEMORY = SLOW_MEMORY
#: Complete batches seen before the slow part is given.
SLOW_MIN = 3
#: Standard errors of the batch means' own scatter an excess must pass before the slow part counts it.
SLOW_SIGNIFICANCE = 2.0
#: What is left of the start's error (``|d|``) when a pair's rows begin to enter the batches.
SLOW_START = 0.01
#: Memory (s) of the untracked tags' mean error that tests the twin's fit.
FIT_MEMORY = 2 * 3600.0
#: False-alarm probability per row of the lack-of-fit test (over all its tags).
FIT_ALPHA = 1e-3
#: Smallest mean error (in the tag's own fast-noise standard deviations) the lack-of-fit test flags.
FIT_EFFECT = 1.0
#: The CSV column of the lack-of-fit statistic.
FIT_COLUMN = "lack_of_fit"


@dataclass(frozen=True)
class Fixed:
    """A parameter the twin holds at an estimate, as one pair's band sees it (part 4 of the module).

    Attributes
    ----------
    name
        The held parameter.
    at_lower, at_upper
        ``truth - p`` of the pair's parameter, in its units, were the plant's value of the held
        parameter at the lower / upper end of its interval (``-Δy/gain``, ``Δy`` the pair's tag's
        change when the twin's held value moves from its estimate to that end).
    """

    name: str
    at_lower: float
    at_upper: float


def fixed_sides(held: Sequence[Fixed]) -> tuple[float, float]:
    """The fixed part's (below, above) extent: each held parameter's shifts toward a side, in quadrature.

    >>> fixed_sides([Fixed("f", -1.0, 3.0), Fixed("g", 4.0, -0.5)])
    (1.118033988749895, 5.0)
    """
    below = math.sqrt(sum(max(0.0, -h.at_lower, -h.at_upper) ** 2 for h in held))
    above = math.sqrt(sum(max(0.0, h.at_lower, h.at_upper) ** 2 for h in held))
    return below, above


def column_names(parameter: str) -> tuple[str, str]:
    """The CSV columns of a tracked parameter's band: ``parameter_lo:<name>``, ``parameter_hi:<name>``."""
    return f"parameter_lo:{parameter}", f"parameter_hi:{parameter}"


@dataclass(frozen=True)
class LoopModel:
    """The linearised loop of one pair (see the module docstring).

    Attributes
    ----------
    impulse
        ``h``: parameter units per unit of measurement noise at sample 0.
    decay
        ``d``: the fraction of an initial parameter error left after each auto sample.
    lag_time
        ``T_lag = Ts Σ d`` (s).
    acf
        ``R_h(l)`` for ``l = 0..NOISE_LAGS``.
    """

    impulse: np.ndarray
    decay: np.ndarray
    lag_time: float
    acf: np.ndarray


def loop_model(gain: float, time_constant: float, kc: float, ti: float, ts: float) -> LoopModel:
    """The linearised loop of a pair with process gain *gain* (variable per parameter unit), first-order
    *time_constant* (s), PI gain *kc* (parameter per variable unit, positive) and integral time *ti*.

    Examples
    --------
    SIMC tuning (``Ti = τ``, ``Kc = 1/(|g| λ)``) makes the loop first order with time constant ``λ τ``;
    sampled, its lag behind a ramp is about that:

    >>> m = loop_model(-2.0, 600.0, 1.0 / (2.0 * 3.0), 600.0, 10.0)
    >>> round(m.lag_time / 1800.0, 1)
    1.0
    """
    s = 1.0 if gain > 0 else -1.0
    a = math.exp(-ts / time_constant) if time_constant > 0 else 0.0
    guess = max(time_constant, ti, abs(1.0 / (gain * kc)) * ti if gain * kc else ti)
    n = int(min(200000, max(200, HORIZON * 4.0 * guess / ts)))

    def run(noise: np.ndarray | None, offset: float) -> np.ndarray:
        # deviation variables: the truth at 0, the parameter starting at *offset*, the twin settled there
        x = p = offset
        e_prev = 0.0
        out = np.empty(n)
        for k in range(n):
            e = (noise[k] if noise is not None else 0.0) - gain * x
            if k == 0:
                e_prev = e if noise is None else 0.0
            p += s * kc * ((e - e_prev) + ts * (e + e_prev) / (2.0 * ti))
            e_prev = e
            out[k] = p
            x = a * x + (1.0 - a) * p
        return out

    impulse_in = np.zeros(n)
    impulse_in[0] = 1.0
    h = run(impulse_in, 0.0)
    d = run(None, 1.0)
    lags = np.arange(NOISE_LAGS + 1)
    acf = np.array([float(h[: n - lag] @ h[lag:]) for lag in lags])
    return LoopModel(h, d, float(ts * np.sum(np.abs(d))), acf)


def loops_impulse(gains: Any, loops: Sequence[tuple[float, float, float, float]], ts: float,
                  errors: bool = False) -> Any:
    """``h[t, j, k]``: parameter ``j``'s response at sample ``t`` to a unit impulse of measurement noise on the tag
    of pair ``k``, the loops together as :func:`loops_noise` describes them; None where they do not settle.
    *errors*: ``(h, s)``, ``s[t, i, k]`` the tracked error of tag ``i``'s response to the same impulse."""
    g = np.asarray(gains, dtype=float)
    m = len(loops)
    sign = np.array([1.0 if lp[0] > 0 else -1.0 for lp in loops])
    tau = np.array([lp[1] for lp in loops])
    kc = np.array([lp[2] for lp in loops])
    ti = np.array([lp[3] for lp in loops])
    a = np.where(tau > 0, np.exp(-ts / np.where(tau > 0, tau, 1.0)), 0.0)
    n = 0
    for gain, t, k, i in loops:
        guess = max(t, i, abs(1.0 / (gain * k)) * i if gain * k else i)
        n = max(n, int(min(200000, max(200, HORIZON * 4.0 * guess / ts))))
    # column k: the loops' response to an impulse on tag k; deviation variables, the twin settled at 0
    z = np.zeros((m, m))
    p = np.zeros((m, m))
    e_prev = np.zeros((m, m))
    h = np.empty((n, m, m))
    s = np.empty((n, m, m))
    for t in range(n):
        e = (np.eye(m) if t == 0 else 0.0) - z
        p = p + (sign * kc)[:, None] * ((e - e_prev) + ts * (e + e_prev) / (2.0 * ti[:, None]))
        e_prev = e
        h[t] = p
        s[t] = e
        z = a[:, None] * z + (1.0 - a)[:, None] * (g @ p)
    peak = float(np.max(np.abs(h))) if np.all(np.isfinite(h)) else math.inf
    if not math.isfinite(peak) or float(np.max(np.abs(h[-max(1, n // 10):]))) > 1e-3 * peak:
        return None
    return (h, s) if errors else h


def loops_noise(gains: Any, loops: Sequence[tuple[float, float, float, float]], ts: float) -> np.ndarray | None:
    """The loops' noise model together (part 5): ``acf[j, k, l]``, the autocorrelation at lag ``l`` of parameter
    ``j``'s response to a unit impulse of measurement noise on the tag of pair ``k``, every tag following all the
    parameters through *gains* with its own pair's first-order lag, each parameter moved by its own PI law
    (*loops*: per pair ``(gain, time_constant, kc, ti)`` as :func:`loop_model` takes them; ``gain`` sets the
    controller's sign). None where the loops together do not settle (their responses have not decayed).

    One pair reduces to :func:`loop_model`'s ``acf``:

    >>> a = loops_noise([[-2.0]], [(-2.0, 600.0, 1.0 / 6.0, 600.0)], 10.0)
    >>> bool(np.allclose(a[0, 0], loop_model(-2.0, 600.0, 1.0 / 6.0, 600.0, 10.0).acf, rtol=1e-9))
    True
    """
    h = loops_impulse(gains, loops, ts)
    return None if h is None else impulse_acf(h)


def impulse_acf(h: np.ndarray) -> np.ndarray:
    """``acf[j, k, l]`` of :func:`loops_noise` from the impulse responses ``h[t, j, k]``."""
    n, m = h.shape[0], h.shape[1]
    lags = range(NOISE_LAGS + 1)
    return np.array([[[float(h[: n - lag, j, k] @ h[lag:, j, k]) for lag in lags] for k in range(m)]
                     for j in range(m)])


def batch_weights(h: np.ndarray, batch: int) -> np.ndarray:
    """The slow part's weights (part 6): ``w[j, k, q] = Σ_l (1 - |l|/N) Σ_t h[t, j, k] h[t + l, j, q]`` over
    ``|l| < N`` (*batch* ``= N``), so that tag errors whose covariance at lag ``l`` is ``C (1 - |l|/N)`` (a
    spectrum of level ``N C`` below the batch's frequency, the batch means' covariance ``C``) give parameter ``j``
    the variance ``Σ_kq C[k, q] w[j, k, q]``. Computed as ``(1/N) Σ_u S_jk(u) S_jq(u)``, ``S`` the moving sums
    of ``h`` over ``N`` samples.

    A response shorter than the batch passes the batch means at its full steady gain ``Σ h``:

    >>> w = batch_weights(np.array([0.5, 0.25])[:, None, None], 1000)
    >>> round(float(w[0, 0, 0]), 3)
    0.562
    """
    sums = _moving_sums(h, int(batch))
    return np.einsum("ujk,ujq->jkq", sums, sums) / int(batch)


def _moving_sums(h: np.ndarray, n: int) -> np.ndarray:
    """``S(u) = Σ h(t)`` over ``u - n < t <= u``, for every ``u`` where it is not zero."""
    c = np.concatenate([np.zeros((1,) + h.shape[1:]), np.cumsum(h, axis=0)])  # c[i] = Σ_{t<i} h(t)
    u = np.arange(h.shape[0] + n - 1)
    return c[np.minimum(u + 1, h.shape[0])] - c[np.maximum(u + 1 - n, 0)]


@dataclass
class _PairState:
    """One pair's running state (what :meth:`BandTracker.state_dict` saves)."""

    buf: list[float]
    fast: list[float]
    sums: list[float]
    weight: float
    seen: int
    auto: int
    ewma_fast: float
    ewma_slow: float
    primed: bool
    held_lo: float
    held_hi: float
    slope: float
    rate: list[float]


class BandTracker:
    """The band columns of a tracking run's CSV (see the module docstring).

    Parameters
    ----------
    spec
        The spec (its ``[[pairs]]``, ``[[parameters]]``, ``sample_time``).
    columns
        The CSV's columns (``time``, ``measured:<tag>``, ``tracked:<tag>``,
        ``parameter:<name>``, ``mode:<tag>``, ...), to find each pair's values in a row.
    level
        Confidence level of the bands.
    fixed
        Per tracked parameter, the parameters the twin holds at an estimate (:class:`Fixed`; part 4
        of the module). None or a parameter left out: no fixed part for it.
    note
        Why held parameters with an interval got no fixed part (``result.json``'s ``fixed_note``).
    gains
        ``G``: the tracked parameters' steady gains on the paired tags (tag of pair ``i`` per unit of the
        parameter of pair ``j``; part 5 of the module). None: each band from its own loop alone.
    misfit
        Untracked tag -> its closed-loop gain per pair (:func:`trackingbox.identify.misfit.closed_gains`, the
        pairs' order): the model-error part (7). None, or a tag left out: no model-error part from it.
    """

    def __init__(self, spec: Any, columns: Sequence[str], level: float = LEVEL,
                 fixed: Mapping[str, Sequence[Fixed]] | None = None, note: str = "",
                 gains: Any = None, misfit: Mapping[str, Sequence[float]] | None = None) -> None:
        self.fixed_note = str(note)  # before the pairs' loop below, which has its own ``note``
        n = len(getattr(spec, "pairs", ()))
        self.gains = None if gains is None else np.asarray(gains, dtype=float)
        if self.gains is not None and (self.gains.shape != (n, n) or not np.all(np.isfinite(self.gains))):
            raise ValueError(f"the loops' gain matrix must be a finite {n} x {n} matrix (one row and column per "
                             f"pair), got shape {self.gains.shape}")
        #: the loops' interaction (part 5 of the module): ``M = G⁻¹ diag(G)``, pairs in the spec's order; None: none
        self.coupling = None if self.gains is None else np.linalg.solve(self.gains, np.diag(np.diag(self.gains)))
        self.coupling_rows = [] if self.coupling is None else [[float(m) for m in row] for row in self.coupling]
        self.carry = None if self.gains is None else follows(self.gains)  # part 7's readings carried (.misfit)
        self.ts = float(spec.sample_time)
        self.z = float(norm.ppf(0.5 + level / 2.0))
        self.level = float(level)
        index = {c: i for i, c in enumerate(columns)}
        self.pairs: list[dict[str, Any]] = []
        for pair in spec.pairs:
            p = spec.parameter(pair.parameter)
            settings = pair_settings(pair, p.min, p.max, ts=self.ts, where=str(getattr(spec, "path", "the spec")))
            kc = settings.kp * (p.max - p.min) / settings.scaling.span
            model = None
            note = ""
            if getattr(pair, "controller", "pi") == "pi":
                model = loop_model(float(pair.gain), float(pair.time_constant), kc, settings.ti, self.ts)
            else:
                note = f"no band: {pair.controller} controllers are not modelled (PI only)"
            interval = getattr(p, "interval", None)
            start_lo, start_hi = (interval if interval is not None else (p.min, p.max))
            kept = tuple((fixed or {}).get(pair.parameter, ()))
            self.pairs.append({"fixed": kept, "fixed_sides": fixed_sides(kept),
                "loop": (float(pair.gain), float(pair.time_constant), kc, float(settings.ti)),
                "parameter": pair.parameter, "variable": pair.variable, "model": model, "note": note,
                "p0": float(p.start), "lo": float(p.min), "hi": float(p.max),
                "start": (float(start_lo), float(start_hi)), "start_source": "interval" if interval else "bounds",
                "cols": (index["time"], index[f"measured:{pair.variable}"], index[f"tracked:{pair.variable}"],
                         index[f"parameter:{pair.parameter}"], index[f"mode:{pair.variable}"])})
        # the loops' noise through their interaction (part 5): None without gains or where a loop is not a PI's
        self.cross_acf = None
        joint = None
        if self.gains is not None and all(pr["model"] is not None for pr in self.pairs):
            joint = loops_impulse(self.gains, [pr["loop"] for pr in self.pairs], self.ts, errors=True)
            self.cross_acf = None if joint is None else impulse_acf(joint[0])
        # what the bands take as exact: the twin's fixed values and the parameters no pair tracks (held at
        # their starts), less those given a fixed part (named per pair by describe())
        tracked = {pr["parameter"] for pr in self.pairs}
        self.assumed = sorted(set(getattr(spec, "fixed", None) or {})
                              | {q.name for q in getattr(spec, "parameters", ()) if q.name not in tracked})
        self.window = max(3, int(round(FLOOR_SPAN / self.ts)) | 1)
        self.forget = math.exp(-self.ts / NOISE_MEMORY)
        self.states = [self._fresh() for _ in self.pairs]
        # the slow part (6): batch means of the paired tags' errors over the slowest loop's lag time
        lags = [pr["model"].lag_time for pr in self.pairs if pr["model"] is not None]
        self.batch = max(1, int(round(max(lags, default=0.0) / self.ts)))
        self.slow_forget = math.exp(-self.batch * self.ts / SLOW_MEMORY)
        for pr in self.pairs:  # the first auto sample from which the start's error stays below SLOW_START
            d = np.abs(pr["model"].decay) if pr["model"] is not None else np.zeros(1)
            big = np.nonzero(d >= SLOW_START)[0]
            pr["faded"] = int(big[-1]) + 1 if big.size else 0
        self.slow = self._slow_fresh()
        n_pairs, nb = len(self.pairs), self.batch
        # the weights w[j, k, q] (batch_weights) and what white fast error of unit level on tag q puts into the
        # batch means of tags i and k: fast[i, k, q] = Σ_u S_iq(u) S_kq(u) / N², S the moving sums of the tracked
        # errors' impulse responses (through the loops: a loop hides its own tag's error from it)
        self.slow_weights = np.zeros((n_pairs, n_pairs, n_pairs))
        self.slow_fast = np.zeros((n_pairs, n_pairs, n_pairs))
        if joint is not None:  # the loops together
            self.slow_weights = batch_weights(joint[0], nb)
            sums = _moving_sums(joint[1], nb)
            self.slow_fast = np.einsum("uiq,ukq->ikq", sums, sums) / (nb * nb)
        else:  # each pair's own loop
            for j, pr in enumerate(self.pairs):
                if pr["model"] is not None:
                    h, err = loops_impulse([[pr["loop"][0]]], [pr["loop"]], self.ts, errors=True) or (None, None)
                    if h is not None:
                        self.slow_weights[j, j, j] = batch_weights(h, nb)[0, 0, 0]
                        self.slow_fast[j, j, j] = float(np.sum(_moving_sums(err, nb)[:, 0, 0] ** 2)) / (nb * nb)
        # the lack-of-fit test: output tags no pair tracks (measured and tracked in the CSV)
        paired = {pr["variable"] for pr in self.pairs}
        self.fit_tags = [c.split(":", 1)[1] for c in columns if c.startswith("measured:")
                         and c.split(":", 1)[1] not in paired and f"tracked:{c.split(':', 1)[1]}" in index]
        self.fit_cols = [(index[f"measured:{t}"], index[f"tracked:{t}"]) for t in self.fit_tags]
        self.fit_lambda = math.exp(-self.ts / FIT_MEMORY)
        self.fit_lambda_short = math.exp(-self.ts / (0.5 * FIT_MEMORY))  # the trend's second mean (.misfit)
        self.fit_z = float(norm.ppf(1.0 - FIT_ALPHA / (2.0 * max(len(self.fit_tags), 1))))
        self.fit_states = [self._fresh() for _ in self.fit_tags]
        self.fit_rows = [0, 0]  # rows with the statistic known, of them at or above 1
        self.fit_worst: dict[str, int] = {}
        # the model-error part (7): each untracked tag's closed-loop gains, NaN where not measured
        self.misfit = np.array([[float(v) for v in (misfit or {}).get(t, [math.nan] * n)] for t in self.fit_tags],
                               dtype=float).reshape(len(self.fit_tags), n)
        if self.misfit.size and not np.any(np.isfinite(self.misfit)):
            self.misfit = np.zeros((0, n))
        # the last row's (mean error, beyond chance, margin), then the same of each tag's trend reading
        self.fit_last: list[tuple[float, bool, float]] = []
        self.misfit_rows = [0] * n  # rows the model-error part widened, per pair

    def _slow_fresh(self) -> dict[str, Any]:
        n = len(self.pairs)
        return {"acc": [0.0] * n, "count": 0, "cov": [[0.0] * n for _ in range(n)], "weight": 0.0, "weight2": 0.0,
                "batches": 0}

    def _slow_add(self, errors: Sequence[float]) -> None:
        """Add one row's paired-tag errors (NaN: a hold or a gap, which drops the batch under way) to the
        slow part's batch means."""
        sl = self.slow
        if not all(math.isfinite(e) for e in errors):
            sl["acc"], sl["count"] = [0.0] * len(errors), 0
            return
        sl["acc"] = [a + e for a, e in zip(sl["acc"], errors)]
        sl["count"] += 1
        if sl["count"] < self.batch:
            return
        mean = [a / self.batch for a in sl["acc"]]
        lam = self.slow_forget
        sl["cov"] = [[lam * c + mi * mk for c, mk in zip(row, mean)] for row, mi in zip(sl["cov"], mean)]
        sl["weight"] = lam * sl["weight"] + 1.0
        sl["weight2"] = lam * lam * sl["weight2"] + 1.0
        sl["batches"] += 1
        sl["acc"], sl["count"] = [0.0] * len(errors), 0

    def _slow_var(self, parts: Sequence[tuple[Any, ...] | None]) -> np.ndarray | None:
        """The slow part's variance per pair (part 6 of the module; None until :data:`SLOW_MIN` batches)."""
        sl = self.slow
        if self.batch * self.ts <= FLOOR_SPAN or sl["batches"] < SLOW_MIN or sl["weight"] <= 0:
            return None  # a loop faster than the fast error's window: the noise part holds its time scale
        cov = np.asarray(sl["cov"], dtype=float) / sl["weight"]
        taper = 1.0 - np.arange(NOISE_LAGS + 1) / (NOISE_LAGS + 1.0)
        fast = np.zeros_like(cov)
        for q, (part, pr) in enumerate(zip(parts, self.pairs)):  # what the fast error alone puts there
            if part is None:
                if pr["model"] is not None:
                    return None  # its fast level not known yet
                continue
            gam = part[7]
            fast += (gam[0] + 2.0 * float(np.sum((taper * gam)[1:]))) * self.slow_fast[:, :, q]
        # beyond the estimate's own scatter: a quadratic form of n_eff batch means, relative sd sqrt(2 / n_eff)
        scatter = SLOW_SIGNIFICANCE * math.sqrt(2.0 * sl["weight2"]) / sl["weight"]
        seen = np.einsum("kq,jkq->j", cov, self.slow_weights)
        return np.maximum(seen - (1.0 + scatter) * np.einsum("kq,jkq->j", fast, self.slow_weights), 0.0)

    def _fresh(self) -> _PairState:
        return _PairState([], [], [0.0] * (NOISE_LAGS + 1), 0.0, 0, 0, 0.0, 0.0, False, 0.0, 0.0, 0.0, [0.0] * 7)

    @property
    def columns(self) -> list[str]:
        """The extra CSV columns, two per pair, and :data:`FIT_COLUMN` where some output is untracked."""
        return [c for pr in self.pairs for c in column_names(pr["parameter"])] + ([FIT_COLUMN] if self.fit_tags else [])

    def _fit(self, values: Sequence[Any]) -> float:
        """The lack-of-fit statistic of one row (see the module)."""
        lam = self.fit_lambda
        worst, which = -1.0, ""
        known = bool(self.fit_tags)
        taper = 1.0 - np.arange(NOISE_LAGS + 1) / (NOISE_LAGS + 1.0)
        self.fit_last, trends = [], []
        for tag, (im, itr), st in zip(self.fit_tags, self.fit_cols, self.fit_states):
            meas, tracked = _num(values[im]), _num(values[itr])
            e = meas - tracked if (math.isfinite(meas) and math.isfinite(tracked)) else math.nan
            self._noise(st, e)
            if math.isfinite(e):
                # the exponential mean (ewma_fast) and its weight (ewma_slow) fill from zero
                st.ewma_fast = lam * st.ewma_fast + (1.0 - lam) * e
                st.ewma_slow = lam * st.ewma_slow + (1.0 - lam)
                st.auto += 1
                # an untracked tag's ``rate`` holds the trend's half-memory mean: its weight and value (.misfit)
                ls = self.fit_lambda_short
                st.rate[0], st.rate[1] = ls * st.rate[0] + (1.0 - ls), ls * st.rate[1] + (1.0 - ls) * e
            if st.seen * self.ts < NOISE_MIN or st.weight <= 0 or st.auto * self.ts < FIT_MEMORY:
                known = False
                self.fit_last.append((math.nan, False, 0.0))
                trends.append((math.nan, False, 0.0))
                continue
            gam = np.asarray(st.sums) / st.weight * (self.window / (self.window - 1.0))
            lrv = gam[0] + 2.0 * float(np.sum((taper * gam)[1:]))
            sd = math.sqrt(max(lrv, 1e-300) * (1.0 - lam) / (1.0 + lam))
            m = abs(st.ewma_fast / st.ewma_slow)
            # beyond the noise twice over: not a chance mean (z), and as large as the noise itself (effect)
            z = min(m / sd / self.fit_z, m / (FIT_EFFECT * math.sqrt(max(float(gam[0]), 1e-300))))
            # the model-error part (7): the signed mean where it is beyond chance, with its own 95 % margin
            self.fit_last.append((st.ewma_fast / st.ewma_slow, m >= sd * self.fit_z, self.z * sd))
            trends.append(trend_reading(st.rate[:2], self.fit_last[-1][0], st.auto, (self.fit_lambda_short, lam),
                                        max(lrv, 1e-300), self.fit_z, self.z))
            if z > worst:
                worst, which = z, tag
        self.fit_last += trends
        if not known or worst < 0:
            return math.nan
        stat = worst
        self.fit_rows[0] += 1
        if stat >= 1.0:
            self.fit_rows[1] += 1
            self.fit_worst[which] = self.fit_worst.get(which, 0) + 1
        return stat

    # -- one row ---------------------------------------------------------------
    def _update(self, pr: dict[str, Any], st: _PairState, meas: float, tracked: float, p: float,
                hold: bool) -> tuple[float, float, float, float, float, float, float] | None:
        """One row of a pair: its parts about ``p`` (None where it has no band yet): the squared noise part, the
        squared start part below and above, the lag below and above and the hold drift below and above (the
        last four added linearly)."""
        model: LoopModel | None = pr["model"]
        if model is None or not math.isfinite(p):
            return None
        e = meas - tracked if (math.isfinite(meas) and math.isfinite(tracked) and not hold) else math.nan
        self._noise(st, e)
        T = model.lag_time
        st.rate[6] += 1.0  # rows seen: the rate's clock runs through holds, as the truth does
        if hold:
            step = abs(st.slope) * self.ts
            if st.slope > 0:
                st.held_hi += step
            elif st.slope < 0:
                st.held_lo += step
        else:
            fade = math.exp(-self.ts / T) if T > 0 else 0.0
            st.held_lo *= fade
            st.held_hi *= fade
            st.slope = self._rate(st, p, T)
            st.auto += 1
        if st.seen * self.ts < NOISE_MIN or st.weight <= 0:
            return None
        gam = np.asarray(st.sums) / st.weight * (self.window / (self.window - 1.0))
        taper = 1.0 - np.arange(NOISE_LAGS + 1) / (NOISE_LAGS + 1.0)
        var = gam[0] * model.acf[0] + 2.0 * float(np.sum((taper * gam * model.acf)[1:]))
        noise = self.z * math.sqrt(max(var, 0.0))
        d = model.decay[st.auto] if st.auto < model.decay.size else 0.0
        a, b = pr["start"]
        below, above = (pr["p0"] - a) * abs(d), (b - pr["p0"]) * abs(d)
        if d < 0:
            below, above = above, below
        lag = abs(st.slope) * T
        return (noise * noise, below * below, above * above, (lag if st.slope < 0 else 0.0),
                (lag if st.slope > 0 else 0.0), st.held_lo, st.held_hi, gam)

    def _rate(self, st: _PairState, p: float, lag: float) -> float:
        """The lag part's rate (part 3 of the module): the slope between two exponential means of the auto rows'
        ``p`` over ``W/2`` and ``W`` (``W`` :data:`RATE_MEMORY`, at least the loop's lag *lag*), each with the
        mean of its rows' times, so ``(P_W/2 - P_W) / (t_W/2 - t_W)`` is exactly a ramp's slope however short
        the history."""
        r = st.rate
        if not st.primed:
            st.ewma_fast, st.primed = p, True  # the reference value: the means are of p - p_first
        x, k = p - st.ewma_fast, r[6]
        memory = max(RATE_MEMORY, lag)
        for i, m in ((0, 0.5 * memory), (3, memory)):
            lam = math.exp(-self.ts / m)
            r[i] = lam * r[i] + 1.0
            r[i + 1] = lam * r[i + 1] + x
            r[i + 2] = lam * r[i + 2] + k
        dt = (r[2] / r[0] - r[5] / r[3]) * self.ts
        return (r[1] / r[0] - r[4] / r[3]) / dt if dt > 0 else 0.0

    def _band(self, j: int, p: float, parts: Sequence[tuple[float, ...] | None],
              slow: np.ndarray | None = None) -> tuple[float, float]:
        """Pair *j*'s band about its value *p* from every pair's *parts* (:meth:`_update`) and its fixed part: its
        own parts alone, or with :attr:`coupling` every pair's start, lag and hold parts carried through the loops'
        interaction (its own noise part as it is; a pair without a band yet adds nothing to the others')."""
        pr = self.pairs[j]
        own = parts[j]
        if own is None:
            return math.nan, math.nan
        f_below, f_above = pr["fixed_sides"]
        noise2, below2, above2, lag_below, lag_above, held_below, held_above, _ = own
        extra = 0.0 if slow is None else self.z * self.z * float(slow[j])
        if self.coupling is None:
            noise2 += extra
            lo = p - math.sqrt(noise2 + below2 + f_below * f_below) - lag_below - held_below
            hi = p + math.sqrt(noise2 + above2 + f_above * f_above) + lag_above + held_above
            return max(pr["lo"], lo), min(pr["hi"], hi)
        if self.cross_acf is not None:  # every tag's fast error through the loops together
            taper = 1.0 - np.arange(NOISE_LAGS + 1) / (NOISE_LAGS + 1.0)
            var = 0.0
            for acf, part in zip(self.cross_acf[j], parts):
                if part is not None:
                    gam = part[7]
                    var += gam[0] * acf[0] + 2.0 * float(np.sum((taper * gam * acf)[1:]))
            noise2 = self.z * self.z * max(var, 0.0)
        noise2 += extra
        qb = qa = lb = la = 0.0
        for m, part in zip(self.coupling_rows[j], parts):
            if part is None or m == 0.0:
                continue
            b, a = (0, 1) if m > 0 else (1, 0)  # a negative coupling turns the other's sides over
            qb += m * m * part[1 + b]
            qa += m * m * part[1 + a]
            lb += abs(m) * (part[3 + b] + part[5 + b])
            la += abs(m) * (part[3 + a] + part[5 + a])
        lo = p - math.sqrt(noise2 + qb + f_below * f_below) - lb
        hi = p + math.sqrt(noise2 + qa + f_above * f_above) + la
        return max(pr["lo"], lo), min(pr["hi"], hi)

    def _noise(self, st: _PairState, e: float) -> None:
        """Add one error sample to the fast-error statistics (NaN: a gap)."""
        buf = st.buf
        buf.append(e)
        if not math.isfinite(e):
            buf.clear()  # a window across a gap is not used, nor are lags across it
            st.fast.clear()
            return
        if len(buf) > self.window:
            del buf[0]
        if len(buf) < self.window:
            return
        f = buf[self.window // 2] - math.fsum(buf) / self.window
        fast = st.fast
        fast.insert(0, f)
        if len(fast) > NOISE_LAGS + 1:
            fast.pop()
        lam = self.forget
        sums = st.sums
        for lag, g in enumerate(fast):
            sums[lag] = lam * sums[lag] + f * g
        for lag in range(len(fast), NOISE_LAGS + 1):
            sums[lag] *= lam
        st.weight = lam * st.weight + 1.0
        st.seen += 1

    def row(self, values: Sequence[Any]) -> list[float]:
        """The band values of one row (*values* as the CSV writer gets them; modes ``"hold"``/``"auto"``
        or a flag)."""
        out: list[float] = []
        parts, ps, errors = [], [], []
        for pr, st in zip(self.pairs, self.states):
            it, im, itr, ip, imode = pr["cols"]
            mode = values[imode]
            hold = (mode == "hold") if isinstance(mode, str) else bool(mode)
            ps.append(_num(values[ip]))
            meas, tracked = _num(values[im]), _num(values[itr])
            parts.append(self._update(pr, st, meas, tracked, ps[-1], hold))
            # the start's transient is the start part's, not slow error: a pair's rows enter once it has faded
            faded = pr["model"] is None or st.auto >= pr["faded"]
            errors.append(meas - tracked if faded and not hold else math.nan)
        self._slow_add(errors)
        slow = self._slow_var(parts)
        fit = self._fit(values) if self.fit_tags else math.nan
        sides = self._misfit_sides()
        for j, p in enumerate(ps):
            lo, hi = self._band(j, p, parts, slow)
            if sides[j] != (0.0, 0.0) and math.isfinite(lo):
                self.misfit_rows[j] += 1
                lo, hi = max(self.pairs[j]["lo"], lo - sides[j][0]), min(self.pairs[j]["hi"], hi + sides[j][1])
            out.extend((lo, hi))
        if self.fit_tags:
            out.append(fit)
        return out

    def _misfit_sides(self) -> list[tuple[float, float]]:
        """The model-error part (7 of the module) per pair from the last row's lack-of-fit means."""
        if not self.misfit.size or len(self.fit_last) != 2 * len(self.fit_tags):
            return [(0.0, 0.0)] * len(self.pairs)
        return implied_sides([f[0] for f in self.fit_last], [f[1] for f in self.fit_last],
                             np.vstack([self.misfit, self.misfit]),
                             [pr["hi"] - pr["lo"] for pr in self.pairs], [f[2] for f in self.fit_last], self.carry)

    def rows(self, array: np.ndarray) -> list[list[float]]:
        """The band values of rows of numbers (modes as flags: non-zero = hold)."""
        return [self.row(r) for r in np.asarray(array, dtype=float).tolist()]

    def append_text(self, text: str, array: Any) -> str:
        """CSV lines (``\\r\\n``-terminated, as the csv module writes them) with each row's band values
        appended, written as the csv module writes floats (``repr``); *array*: the rows as numbers."""
        if array is None:
            raise ValueError("band columns need the rows as numbers beside their text")
        lines = text.split("\r\n")
        values = self.rows(array)
        if len(lines) != len(values) + 1 or lines[-1] != "":
            raise ValueError(f"{len(values)} rows of numbers for {len(lines) - 1} lines of text")
        return "".join(f"{line},{','.join(map(repr, extra))}\r\n" for line, extra in zip(lines, values))

    # -- state -------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        return {"level": self.level, "pairs": [vars(st).copy() for st in self.states],
                "fit": [vars(st).copy() for st in self.fit_states], "fit_rows": list(self.fit_rows),
                "fit_worst": dict(self.fit_worst), "misfit_rows": list(self.misfit_rows), "slow": {k: (list(map(list, v)) if k == "cov" else
                                                               (list(v) if isinstance(v, list) else v))
                                                           for k, v in self.slow.items()}}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        def load(s: Mapping[str, Any]) -> _PairState:
            return _PairState(**{k: (list(v) if isinstance(v, list) else v) for k, v in s.items()})

        if self.fit_tags and "fit" not in state:
            # its CSV has no lack_of_fit column: the rows appended now would not match its header
            raise CheckpointError("the checkpoint was written before the bands' lack_of_fit column; run without --resume")
        if "slow" not in state:
            raise CheckpointError("the checkpoint was written before the bands' slow part; run without --resume")
        if any("rate" not in s for s in state["pairs"]):
            raise CheckpointError("the checkpoint was written before the bands' day-long rate; run without --resume")
        if any(s["auto"] > 0 and not s["rate"][0] for s in state.get("fit", ())):  # its short mean never filled
            raise CheckpointError("the checkpoint was written before the model-error part's trend; run without --resume")
        self.states = [load(s) for s in state["pairs"]]
        sl = state["slow"]
        self.slow = {"acc": [float(v) for v in sl["acc"]], "count": int(sl["count"]),
                     "cov": [[float(v) for v in row] for row in sl["cov"]], "weight": float(sl["weight"]),
                     "weight2": float(sl["weight2"]),
                     "batches": int(sl["batches"])}
        if "fit" in state:
            self.fit_states = [load(s) for s in state["fit"]]
            self.fit_rows = [int(v) for v in state.get("fit_rows", [0, 0])]
            self.fit_worst = {str(k): int(v) for k, v in state.get("fit_worst", {}).items()}
        self.misfit_rows = [int(v) for v in state.get("misfit_rows", [0] * len(self.pairs))]

    def describe(self) -> dict[str, Any]:
        """The bands' settings per parameter (for ``result.json``)."""
        out: dict[str, Any] = {"level": self.level, "columns": "parameter_lo:<name>, parameter_hi:<name>",
                               "slow": {"batch": self.batch * self.ts, "batches": int(self.slow["batches"]),
                                        "memory": SLOW_MEMORY, "through": "loops together" if
                                        self.cross_acf is not None else "each pair's own loop"}}
        if self.fit_tags:
            known, flagged = self.fit_rows
            out["lack_of_fit"] = {
                "column": FIT_COLUMN, "tags": list(self.fit_tags), "memory": FIT_MEMORY, "alpha": FIT_ALPHA,
                "effect": FIT_EFFECT,
                "z": self.fit_z, "rows": known, "rows_flagged": flagged,
                "share_flagged": flagged / known if known else None,
                "flagged_by": dict(sorted(self.fit_worst.items(), key=lambda kv: -kv[1])),
                "meaning": "at 1 or more an untracked tag disagrees with the twin beyond its noise: " + (
                    "each band reaches the value of its parameter such a tag implies (model_error)" if self.misfit.size
                    else "the bands do not cover that model error")}
        for pr in self.pairs:
            m: LoopModel | None = pr["model"]
            out[pr["parameter"]] = {"variable": pr["variable"], "start": list(pr["start"]),
                                    "start_from": pr["start_source"],
                                    **({"fixed": {h.name: [h.at_lower, h.at_upper] for h in pr["fixed"]}}
                                       if pr["fixed"] else {}),
                                    **({"fixed_note": self.fixed_note} if self.fixed_note else {}),
                                    **({"coupling": {q["parameter"]: float(m) for q, m in
                                                     zip(self.pairs, self.coupling[self.pairs.index(pr)])}}
                                       if self.coupling is not None else {}),
                                    "taken_as_exact": [n for n in self.assumed
                                                       if n not in {h.name for h in pr["fixed"]}],
                                    **({"model_error": {
                                        "closed_gains": {t: float(g[self.pairs.index(pr)])
                                                         for t, g in zip(self.fit_tags, self.misfit)},
                                        "rows_widened": self.misfit_rows[self.pairs.index(pr)]}}
                                       if self.misfit.size else {}),
                                    **({"lag_time": m.lag_time, "noise_gain": math.sqrt(float(m.acf[0]))}
                                       if m is not None else {"note": pr["note"]})}
        return out


def _num(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan
