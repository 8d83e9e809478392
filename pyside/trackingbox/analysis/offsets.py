"""What the untracked twin gets wrong: offsets, sensor noise and what tracking could remove.

Pairing by gains alone does not know whether a pair is *useful*. This module
looks at the data: it runs the twin untracked over a window with the measured
inputs (parameters at their starts, the spec's state compensation holding the
tank levels, as ``track`` does) and compares its outputs with the
measurements.

* :func:`noise_sigma` estimates a sensor's noise level from the measurement
  itself: the robust standard deviation (1.4826 x median absolute deviation)
  of the first differences divided by sqrt(2). White noise of standard
  deviation sigma gives differences of standard deviation sigma*sqrt(2); the
  slow process movement adds little to the differences, and steps are
  outliers the median ignores.
* :func:`reach` tells how far a parameter's remaining range (in the direction
  that closes the mean offset) moves a variable, compared with the offset.
* :func:`predict_tracking` estimates, for a set of pairs, what tracking would
  leave of the error: each loop is taken as a first-order closed loop (time
  constant = the pair's step-response time constant, as the SIMC tuning of
  ``track`` with lambda = 1 gives), so the parameters follow
  ``G^-1 · lowpass(residual)`` clipped to their bounds, and the tracked error
  is ``residual - G · clipped move``. A parameter that would sit at a bound, or
  an error that changes faster than the loop, shows up as a ratio near one.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..data import MeasurementView
from ..errors import AnalysisError, DataError, TrackingError, unknown_name
from ..simulation.models import open_model
from ..tracking.controllers import StateCompensator

if TYPE_CHECKING:
    from ..spec import Spec

logger = logging.getLogger(__name__)

_MAD = 1.482602218505602  # 1 / Phi^-1(3/4): MAD -> standard deviation for normal data


def noise_sigma(values: npt.ArrayLike) -> float:
    """Sensor-noise standard deviation estimated from a measured series.

    ``1.4826 · median(|d - median(d)|) / sqrt(2)`` over the first differences
    ``d`` of consecutive valid samples.

    Parameters
    ----------
    values : array_like
        Equally spaced samples; NaN marks missing samples (differences across
        them are not used).

    Returns
    -------
    float
        The estimate; NaN with fewer than three usable differences.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> round(noise_sigma(np.linspace(0, 1, 20000) + rng.normal(0, 0.1, 20000)), 2)
    0.1
    """
    x = np.asarray(values, dtype=float)
    d = np.diff(x)
    d = d[np.isfinite(d)]
    if d.size < 3:
        return math.nan
    return float(_MAD * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


#: A series whose consecutive samples are equal this often is a held one (a historian's
#: exception reporting laid on the grid by sample-and-hold): its first differences are
#: mostly zero, so :func:`noise_sigma` reads 0 and the noise is taken from :func:`noise_floor`.
HELD_FRACTION = 0.5
#: Span (s) of the centred moving average :func:`noise_floor` measures the spread around.
FLOOR_SPAN = 1800.0
#: Span (s) of the means :func:`loop_jitter` measures the floor's integral time scale from: long
#: against the sample interval, short against :data:`FLOOR_SPAN`.
JITTER_BLOCK = 300.0


def held_fraction(values: npt.ArrayLike) -> float:
    """Fraction of the first differences of consecutive valid samples that are exactly zero.

    >>> held_fraction([1.0, 1.0, 1.0, 2.0, 2.0])
    0.75
    """
    d = np.diff(np.asarray(values, dtype=float))
    d = d[np.isfinite(d)]
    return float(np.mean(d == 0.0)) if d.size else math.nan


def noise_floor(values: npt.ArrayLike, interval: float, span: float = FLOOR_SPAN) -> float:
    """RMS spread of a series around its centred moving average over *span* s.

    For a series that tracking has to follow with loops of hours, what changes
    faster than *span* is a floor no loop removes: the sensor noise and, for an
    exception-reported (dead-band) tag laid on the grid by sample-and-hold, the
    held value's distance from the truth. Only samples whose whole averaging
    window is valid count (stoppages and gaps are NaN); the spread is scaled by
    ``sqrt(w / (w - 1))`` for the ``w`` samples of the window (the mean of white
    noise over them takes ``1/w`` of its variance).

    Parameters
    ----------
    values : array_like
        Equally spaced samples (NaN: missing).
    interval : float
        Sample spacing (s).
    span : float
        Averaging span (s); at least 3 samples.

    Returns
    -------
    float
        The spread; NaN when no full window is valid.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> x = np.sin(np.arange(20000) * 10.0 / 86400.0) + rng.normal(0.0, 0.1, 20000)
    >>> round(noise_floor(x, 10.0), 2)
    0.1
    """
    x = np.asarray(values, dtype=float)
    w = max(3, int(round(span / interval)) | 1)
    if x.size < w:
        return math.nan
    h = _centred_deviation(x, w)
    dev = h[np.isfinite(h)]
    if dev.size == 0:
        return math.nan
    return float(np.sqrt(np.mean(dev ** 2) * w / (w - 1)))


def loop_jitter(values: npt.ArrayLike, interval: float, loop: float, span: float = FLOOR_SPAN,
                block: float = JITTER_BLOCK) -> float:
    """Standard deviation of the move an integrating loop of closed-loop time constant *loop*
    makes from a series' fast part, in the series' units (divide by the gain for the parameter's).

    The fast part is the series' deviation from its centred moving average over *span* s (what
    :func:`noise_floor` counts as the floor: sensor noise, held values, and the twin's errors
    faster than half an hour). It is not white: a level loop's swings and a recovery after a
    stoppage keep it on one side for minutes. Its integral time scale ``tau`` is measured from
    its means over *block* s (``tau = block x var(block means) / var / (1 - block / span)``: the
    block mean of a deviation from the span's mean keeps ``1 - block / span`` of the block mean's
    variance; ``tau`` is the sample interval for white noise; for a correlated noise it reads a
    little low, as ``tau`` is not small against *block*), and a first-order loop of time constant
    ``T >> tau`` passes
    ``sigma x sqrt(tau / (2 T))`` of it. Only samples whose windows are whole and valid count
    (stoppages and gaps are NaN).

    Examples
    --------
    White noise: ``sigma x sqrt(interval / (2 loop))``.

    >>> rng = np.random.default_rng(0)
    >>> x = rng.normal(0.0, 1.0, 100000)
    >>> round(loop_jitter(x, 10.0, 3600.0) / math.sqrt(10.0 / 7200.0), 1)
    1.0

    The same noise held for 30 s at a time (correlated over 3 samples) passes sqrt(3) = 1.73 times as much.

    >>> round(loop_jitter(np.repeat(x[:33334], 3), 10.0, 3600.0) / math.sqrt(10.0 / 7200.0), 2)
    1.65
    """
    x = np.asarray(values, dtype=float)
    w = max(3, int(round(span / interval)) | 1)
    k = max(1, int(round(block / interval)))
    if not (loop > 0 and interval > 0) or x.size < w + k:
        return math.nan
    h = _centred_deviation(x, w)
    ok = np.isfinite(h)
    if ok.sum() < 2 * k:
        return math.nan
    var = float(np.mean(h[ok] ** 2))
    c = np.concatenate([[0.0], np.cumsum(np.where(ok, h, 0.0))])
    n = np.concatenate([[0], np.cumsum(ok)])
    full = (n[k:] - n[:-k]) == k
    if not full.any() or var <= 0:
        return math.nan if not full.any() else 0.0
    means = ((c[k:] - c[:-k]) / k)[full]
    # the block mean of a deviation from the span's mean keeps 1 - k/w of the block mean's variance
    tau = max(interval, k * interval * float(np.mean(means ** 2)) / var / (1.0 - k / w))
    return float(math.sqrt(var * tau / (2.0 * loop)))


def _centred_deviation(x: np.ndarray, w: int) -> np.ndarray:
    """``x`` minus its centred moving average over *w* samples (NaN where the window is not whole)."""
    ok = np.isfinite(x)
    c = np.concatenate([[0.0], np.cumsum(np.where(ok, x, 0.0))])
    n = np.concatenate([[0], np.cumsum(ok)])
    full = (n[w:] - n[:-w]) == w
    out = np.full(x.size, math.nan)
    mid = slice(w // 2, w // 2 + full.size)
    out[mid] = np.where(full, x[mid] - (c[w:] - c[:-w]) / w, math.nan)
    return out


@dataclass(frozen=True)
class OffsetStats:
    """Untracked error of one variable (measured - simulated) over the analysis window.

    Attributes
    ----------
    variable : str
    noise : float
        Sensor noise standard deviation: :func:`noise_sigma` of the measurement, or, for
        a held (exception-reported) series, :func:`noise_floor` of measured - simulated
        (its noise and held values' distance from the truth: what stays with slow loops).
    mean : float
        Mean of ``measured - simulated`` (the offset; its sign says which way to move).
    rms : float
        Root mean square of ``measured - simulated``.
    samples : int
        Valid samples used.
    """

    variable: str
    noise: float
    mean: float
    rms: float
    samples: int

    @property
    def noise_ratio(self) -> float:
        """``rms / noise`` (inf for a noise-free sensor with an error)."""
        if self.noise > 0:
            return self.rms / self.noise
        return math.inf if self.rms > 0 else math.nan


def offset_stats(variable: str, measured: npt.ArrayLike, simulated: npt.ArrayLike,
                 interval: float | None = None) -> OffsetStats:
    """:class:`OffsetStats` of one variable from its measured and untracked simulated series.

    With the grid *interval* (s), a measurement held over more than
    :data:`HELD_FRACTION` of its samples gets its noise from :func:`noise_floor` of
    ``measured - simulated`` (the first differences of a held series are mostly zero).

    Examples
    --------
    >>> s = offset_stats("T", [1.0, 2.0, 3.0, 4.0, 5.0], [0.0, 1.0, 2.0, 3.0, 4.0])
    >>> (s.mean, s.rms, s.noise)
    (1.0, 1.0, 0.0)
    """
    m = np.asarray(measured, dtype=float)
    s = np.asarray(simulated, dtype=float)
    r = m - s
    ok = np.isfinite(r)
    noise = noise_sigma(m)
    if interval is not None and held_fraction(m) > HELD_FRACTION:
        floor = noise_floor(r, interval)
        if math.isfinite(floor):
            noise = max(floor, noise) if math.isfinite(noise) else floor
    if not ok.any():
        return OffsetStats(variable, noise, math.nan, math.nan, 0)
    return OffsetStats(variable, noise, float(r[ok].mean()), float(np.sqrt(np.mean(r[ok] ** 2))),
                       int(ok.sum()))


@dataclass(frozen=True)
class Residuals:
    """Measured and untracked simulated series of the tracking variables on one time grid.

    Attributes
    ----------
    variables : tuple of str
        Tags (rows).
    time : ndarray, shape (n,)
        Seconds from the first measurement sample.
    measured, simulated : ndarray, shape (m, n)
        NaN where the measurement is missing or excluded (stoppage, start-up).
    interval : float
        Grid spacing (s).
    """

    variables: tuple[str, ...]
    time: np.ndarray = field(repr=False, compare=False)
    measured: np.ndarray = field(repr=False, compare=False)
    simulated: np.ndarray = field(repr=False, compare=False)
    interval: float = 10.0

    @property
    def residual(self) -> np.ndarray:
        """``measured - simulated``, shape (m, n)."""
        return self.measured - self.simulated

    def stats(self) -> tuple[OffsetStats, ...]:
        """:class:`OffsetStats` per variable."""
        return tuple(offset_stats(v, self.measured[i], self.simulated[i], self.interval)
                     for i, v in enumerate(self.variables))

    def subset(self, variables: Sequence[str]) -> Residuals:
        """The rows of *variables*, in that order."""
        idx = [self.variables.index(v) for v in variables]
        return Residuals(tuple(variables), self.time, self.measured[idx], self.simulated[idx], self.interval)




def simulate_untracked(spec: Spec, variables: Sequence[str], *, start: float, stop: float,
                       skip: float | None = None, tolerance: float = 1e-6) -> Residuals:
    """Run the twin untracked from the first sample to *stop* and collect *variables*.

    The data come from the spec's measurement view
    (:class:`trackingbox.data.MeasurementView`, the one tracking and validation
    use). The twin gets its input table (gaps filled), the parameter starts and fixed
    values, and the proportional state compensation of the spec's
    ``[[states]]`` (the same correction ``track`` applies to its untracked
    twin). Samples the view does not score (before ``max(start, skip)``,
    inside a stoppage, missing, or in a gap longer than the view's gap limit)
    are NaN in the result.

    Parameters
    ----------
    spec : trackingbox.spec.Spec
    variables : sequence of str
        Tags of ``[outputs]`` to collect.
    start, stop : float
        Analysis window (s from the first sample), ``[start, stop)``.
    skip : float, optional
        Start-up time left out (default: the spec's ``tracking.hold_until``).
    tolerance : float
        FMU solver relative tolerance.

    Returns
    -------
    Residuals

    Raises
    ------
    AnalysisError
        An unknown tag, a window without samples, or a twin that fails.
    """
    for tag in variables:
        if tag not in spec.outputs:
            raise AnalysisError(unknown_name("tag", tag, list(spec.outputs), f"[outputs] of {spec.path}"))
    first = max(float(start), float(spec.tracking.hold_until if skip is None else skip))
    try:
        view = MeasurementView.from_spec(spec, (float(start), float(stop)), skip=first, tags=variables)
    except DataError as exc:
        raise AnalysisError(f"the untracked analysis over [{start:g}, {stop:g}) s: {exc}") from None
    where = view.source.name
    grid = view.grid
    n = grid.size
    ts = view.sample_time
    for tag in spec.inputs:
        if not np.isfinite(view.values(tag)).any():
            raise AnalysisError(f"input tag {tag!r} in {where} has no valid value before {grid[-1]:g} s")
    base = {p.name: p.start for p in spec.parameters}
    base.update(spec.fixed)
    outs = [spec.outputs[v] for v in variables]
    levels = [s.variable for s in spec.states]
    comps = [StateCompensator(s.gain, ts=ts) for s in spec.states]
    level_meas = [view.values(s.tag) for s in spec.states]
    sim = np.full((len(outs), n), math.nan)
    model = open_model(spec.twin, tolerance=tolerance)
    try:
        stepper = model.stepper(start_time=0.0, parameters={**base, **{s.correction: 0.0 for s in spec.states}},
                                inputs=view.inputs)
        for k in range(n):
            sim[:, k] = stepper.get(outs)
            if k == n - 1:
                break
            if spec.states:
                lv = stepper.get(levels)
                stepper.set({s.correction: c.update(float(lm[k]), float(x))
                             for s, c, lm, x in zip(spec.states, comps, level_meas, lv)})
            stepper.step(float(grid[k + 1]))
    except TrackingError as exc:
        raise AnalysisError(f"the untracked twin failed over the training window: {exc}") from None
    finally:
        model.close()
    # scored: valid, inside [start, stop), after the start-up skip, not in a stoppage
    scored = np.array([view.scored[v] for v in variables]).reshape(len(variables), n)
    meas = np.array([view.values(v) for v in variables]).reshape(len(variables), n)
    meas[~scored] = math.nan
    sim[~scored] = math.nan
    keep = grid >= float(start) - 1e-9
    return Residuals(tuple(variables), grid[keep], meas[:, keep], sim[:, keep], ts)


def reach(gain: float, offset: float, start: float, lower: float, upper: float) -> tuple[float, float]:
    """How far a parameter's remaining range moves a variable, against the offset to close.

    The move needed is ``offset / gain``; the range available in that direction
    is ``upper - start`` (upward) or ``start - lower`` (downward).

    Parameters
    ----------
    gain : float
        Steady-state gain ``d variable / d parameter``.
    offset : float
        Mean ``measured - simulated``.
    start, lower, upper : float
        Parameter start and bounds.

    Returns
    -------
    moves : float
        ``|gain| x available range``: how far the parameter can move the variable
        toward the measurement.
    fraction : float
        ``moves / |offset|`` (inf for a zero offset, 0 for a zero gain).

    Examples
    --------
    >>> reach(0.5, 2.0, 10.0, 0.0, 12.0)     # needs +4, has +2: closes half
    (1.0, 0.5)
    >>> reach(0.5, -2.0, 10.0, 0.0, 12.0)    # needs -4, has -10
    (5.0, 2.5)
    """
    if gain == 0.0 or not math.isfinite(gain):
        return 0.0, 0.0
    need = offset / gain
    available = (upper - start) if need > 0 else (start - lower)
    moves = abs(gain) * max(available, 0.0)
    return moves, (moves / abs(offset) if offset != 0 else math.inf)


def lowpass(x: npt.ArrayLike, tau: float, dt: float, initial: float = 0.0) -> np.ndarray:
    """First-order low-pass ``y_k = a·y_{k-1} + (1 - a)·x_k``, ``a = exp(-dt/tau)``; NaN samples hold ``y``.

    ``y_{-1} = initial`` (0: a loop that starts with no correction).

    Examples
    --------
    >>> lowpass([1.0, 1.0, 1.0], tau=1e-9, dt=1.0).tolist()
    [1.0, 1.0, 1.0]
    >>> [round(float(v), 3) for v in lowpass([1.0, 1.0], tau=1.0, dt=math.log(2.0))]
    [0.5, 0.75]
    """
# deferred (start-up): scipy.signal adds 0.45-0.54 s to an import of the package (python -X importtime,
    # on top of numpy/pandas/scipy.optimize) for one filter call
    from scipy.signal import lfilter

    v = np.asarray(x, dtype=float)
    if v.size == 0:
        return v.copy()
    a = math.exp(-dt / tau) if tau > 0 else 0.0
    ok = np.isfinite(v)
    # a NaN sample holds y: feed the filter its own previous output there (y_k = a y + (1-a) y = y)
    if ok.all():
        y, _ = lfilter([1.0 - a], [1.0, -a], v, zi=[a * initial])
        return np.asarray(y)
    y = np.empty_like(v)
    state = float(initial)
    for k, xk in enumerate(v):
        if math.isfinite(xk):
            state = a * state + (1.0 - a) * xk
        y[k] = state
    return y


@dataclass(frozen=True)
class TrackingPrediction:
    """What :func:`predict_tracking` expects of a set of pairs.

    Attributes
    ----------
    ratio : ndarray, shape (k,)
        Expected tracked/untracked RMS ratio per paired variable.
    at_bound : ndarray, shape (k,)
        Fraction of samples where the parameter would be held at a bound.
    need : ndarray, shape (k,)
        Mean parameter move that closes the mean offsets of all pairs together
        (``G^-1 · mean offset``), as a fraction of the range available in its
        direction (above 1: beyond the bound).
    """

    ratio: np.ndarray
    at_bound: np.ndarray
    need: np.ndarray


def predict_tracking(gains: npt.ArrayLike, time_constants: npt.ArrayLike, residual: npt.ArrayLike,
                     lower: npt.ArrayLike, upper: npt.ArrayLike, dt: float, settle: float = 0.0) -> TrackingPrediction:
    """Expected effect of tracking a square set of pairs (linear, first-order loops).

    Parameters
    ----------
    gains : array_like, shape (k, k)
        ``G[a, b] = d variable_a / d parameter_b`` for the paired variables and
        parameters (parameter ``b`` is paired with variable ``b``).
    time_constants : array_like, shape (k,)
        Closed-loop time constant of each loop (s).
    residual : array_like, shape (k, n)
        Untracked ``measured - simulated`` (NaN where missing).
    lower, upper : array_like, shape (k,)
        Parameter bounds relative to the start (``min - start <= 0 <= max - start``).
    dt : float
        Sample spacing (s).
    settle : float
        s from the first sample before the ratio and the time at a bound count: tracking is
        judged once its loops settled (the loops start from no correction at the first
        sample; a slow loop's start-up transient would otherwise decide the figure); at
        most the first half of the samples are skipped (a short window keeps its second half).

    Returns
    -------
    TrackingPrediction

    Raises
    ------
    AnalysisError
        If the gain matrix is singular.
    """
    G = np.atleast_2d(np.asarray(gains, dtype=float))
    R = np.atleast_2d(np.asarray(residual, dtype=float))
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    tau = np.asarray(time_constants, dtype=float)
    k = G.shape[0]
    if G.shape != (k, k) or R.shape[0] != k:
        raise AnalysisError(f"predict_tracking: gains {G.shape} and residuals {R.shape} do not match")
    try:
        Ginv = np.linalg.inv(G)
    except np.linalg.LinAlgError:
        raise AnalysisError("predict_tracking: the gain matrix of the pairs is singular") from None
    ok = np.all(np.isfinite(R), axis=0)
    ok[: min(ok.size // 2, int(math.ceil(max(float(settle), 0.0) / dt - 1e-9)))] = False
    if not ok.any():
        nan = np.full(k, math.nan)
        return TrackingPrediction(nan, nan, nan)
    filtered = np.array([lowpass(R[a], float(tau[a]), dt) for a in range(k)])
    moves = Ginv @ filtered
    clipped = np.clip(moves, lo[:, None], hi[:, None])
    tracked = R - G @ clipped
    with np.errstate(all="ignore"):
        ratio = np.sqrt(np.mean(tracked[:, ok] ** 2, axis=1) / np.mean(R[:, ok] ** 2, axis=1))
        at_bound = np.mean((moves[:, ok] < lo[:, None]) | (moves[:, ok] > hi[:, None]), axis=1)
        mean_move = Ginv @ R[:, ok].mean(axis=1)
        avail = np.where(mean_move > 0, hi, -lo)
        need = np.where(avail > 0, np.abs(mean_move) / avail, np.inf)
    return TrackingPrediction(ratio, at_bound, need)
