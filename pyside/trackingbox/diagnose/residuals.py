"""Where twin and plant disagree: the null model's residual, tag by tag, against the tag's noise.

The *null model* is the twin with the spec's candidate ``[[parameters]]`` fitted on
the training window (:func:`trackingbox.estimation.estimate`), so that a plain
parameter error is never taken for a missing effect. For every output tag the
residual ``r = measured - simulated`` on the window's scored samples is described
against the tag's noise level ``sigma`` estimated from the measurements themselves
(:func:`noise_sigma`):

* ``offset``: the mean residual;
* ``trend``: the least-squares slope of the residual in time (tag units per hour);
* ``conditions``: the regression of the residual on the standardised inputs
  (coefficient per input tag, in tag units per input standard deviation, and the
  share of the residual variance it explains);
* ``lag``: the regression of the residual on the simulated output's time
  derivative; a measurement lagging the process by a first-order time constant
  ``tau`` reads ``y - tau * dy/dt`` to first order, so ``lag_seconds = -slope``;
* ``stoppages``: the residual RMS in the settle periods after stoppages against
  the rest;
* ``periods``: the window cut into blocks; a block whose mean residual exceeds
  :data:`PERIOD_THRESHOLD` noise standard deviations is a significant period.

The noise a tag is judged against has two parts: the sensor's own noise, and the
spread that the noise of the measured *inputs* causes in the simulated output
(:func:`propagated_noise`). The twin is driven by the measured inputs, noise
included, while the plant ran on the true ones; a controller output with no
sensor noise of its own (a pump speed, a valve position) still differs from the
plant's by what its controller made of the noisy input it was fed. That spread is
measured, not assumed: the null model is simulated once more with every input
perturbed by an independent draw of that input's own noise, and the RMS change of
each output is its propagated noise. The two add in quadrature.

A tag is *significant* when its residual is larger than its noise allows:
``rms(r) > RMS_THRESHOLD * sigma``, or ``|offset| > OFFSET_THRESHOLD * sigma``, or
a trend moving the residual by more than ``OFFSET_THRESHOLD * sigma`` over the
window. (A white residual of the noise alone has ``rms / sigma`` close to 1 and a
mean and trend of order ``sigma / sqrt(n)``.)

Balances (``[[balances]]`` in the spec: a sum of signed measured tags that
should vanish) are checked on the measurements alone: one that does not close
points at a faulty sensor among its tags; one that closes while the twin's
residual is significant points at a process change the twin lacks.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ..analysis.offsets import noise_floor
from ..data import MeasurementView
from ..estimation import estimate, jacobian_points
from ..simulation.models import close_models
from ..simulation.windows import load_windows, problem_from_spec, simulate_window
from .parallel import map_calls
from .linear import fit_windows, joint_lstsq, step_bounds
from .varying import VaryingBasis, basis_for

if TYPE_CHECKING:
    from ..estimation import EstimationResult
    from ..simulation.windows import Problem, WindowData
    from ..spec import Spec

log = logging.getLogger(__name__)

#: A tag is significant when the residual RMS exceeds this many noise standard deviations.
RMS_THRESHOLD = 1.5
#: ... or its mean (or its trend over the window) exceeds this many noise standard deviations.
OFFSET_THRESHOLD = 1.0
#: A period (block of the window) is significant when its mean residual exceeds this many sigmas.
PERIOD_THRESHOLD = 1.0
#: Seed of the input-noise draw :func:`propagated_noise` simulates with (fixed: the same data give the same verdict).
PROPAGATION_SEED = 7
#: Number of blocks the heat map and the periods cut a window into.
DEFAULT_BLOCKS = 12
#: Smallest noise level a tag is given, as a fraction of its measured range over the record: a
#: signal with (almost) no noise, such as a controller output or a speed, is judged against its
#: resolution instead of a near-zero sigma.
NOISE_FLOOR = 1.0e-3


# --------------------------------------------------------------------------- numerics


def noise_sigma(values: npt.ArrayLike) -> float:
    """Standard deviation of the white measurement noise in a series, from its high frequencies.

    The second difference ``d_k = y_{k+1} - 2 y_k + y_{k-1}`` removes a signal
    that is smooth on the sampling scale (a linear piece exactly) and leaves
    ``e_{k+1} - 2 e_k + e_{k-1}`` of white noise ``e``, whose variance is
    ``6 sigma**2``. The spread of ``d`` is taken robustly (1.4826 times the median
    absolute deviation), so steps in the signal do not inflate it. NaN samples
    break the series: only differences of three valid neighbours count.

    Parameters
    ----------
    values
        Equally spaced samples.

    Returns
    -------
    float
        The estimated sigma (NaN with fewer than 5 usable differences).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t = np.arange(5000.0)
    >>> round(noise_sigma(np.sin(t / 300.0) + rng.normal(0.0, 0.2, t.size)), 2)
    0.2
    """
    y = np.asarray(values, dtype=float)
    if y.size < 3:
        return math.nan
    d = y[2:] - 2.0 * y[1:-1] + y[:-2]
    d = d[np.isfinite(d)]
    if d.size < 5:
        return math.nan
    mad = float(np.median(np.abs(d - np.median(d))))
    return 1.4826 * mad / math.sqrt(6.0)


def noise_level(values: npt.ArrayLike) -> float:
    """:func:`noise_sigma`, at least :data:`NOISE_FLOOR` times the series' range (NaN ignored).

    >>> noise_level(np.linspace(0.0, 10.0, 101))   # a noise-free ramp: its resolution floor
    0.01
    """
    y = np.asarray(values, dtype=float)
    ok = np.isfinite(y)
    sigma = noise_sigma(y)
    span = float(y[ok].max() - y[ok].min()) if ok.any() else 0.0
    floor = NOISE_FLOOR * span
    if not math.isfinite(sigma):
        return floor if floor > 0 else math.nan
    return max(sigma, floor)


def ljung_box_lag1(residual: npt.ArrayLike) -> float:
    """Lag-one autocorrelation of a residual (NaN samples dropped): ~0 for white noise.

    >>> round(ljung_box_lag1([1.0, -1.0, 1.0, -1.0, 1.0, -1.0]), 3)
    -0.833
    """
    r = np.asarray(residual, dtype=float)
    r = r[np.isfinite(r)]
    if r.size < 3:
        return math.nan
    r = r - r.mean()
    den = float(np.dot(r, r))
    return float(np.dot(r[:-1], r[1:]) / den) if den > 0 else 0.0


def _lstsq(columns: Sequence[np.ndarray], y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.column_stack(columns)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return coef, y - a @ coef


@dataclass(frozen=True)
class TagResidual:
    """How one tag's residual departs from its noise.

    Attributes
    ----------
    tag
        The output tag.
    noise
        Noise standard deviation estimated from the measured series (tag units).
    rms
        Residual root mean square (tag units).
    offset
        Mean residual (tag units).
    trend
        Residual slope in time (tag units per hour).
    lag_seconds
        First-order lag the residual's correlation with ``-dy_sim/dt`` indicates (s).
    lag_correlation
        Correlation of the residual with ``-dy_sim/dt``.
    conditions
        Input tag -> residual change per standard deviation of that input (tag units).
    conditions_r2
        Share of the residual variance the inputs explain (linear regression).
    stoppage_rms
        Residual RMS in the settle periods after stoppages (NaN without any).
    whiteness
        Lag-one autocorrelation of the residual.
    periods
        ``(start, stop)`` seconds of the blocks whose mean residual exceeds the threshold.
    blocks
        Block mean of the residual in noise sigmas (the heat-map row).
    block_edges
        Block boundaries (s), ``len(blocks) + 1`` values.
    samples
        Number of scored samples.
    significant
        The residual is larger than the noise allows (module docstring).
    """

    tag: str
    noise: float
    rms: float
    offset: float
    trend: float
    lag_seconds: float
    lag_correlation: float
    conditions: dict[str, float]
    conditions_r2: float
    stoppage_rms: float
    whiteness: float
    periods: tuple[tuple[float, float], ...]
    blocks: tuple[float, ...]
    block_edges: tuple[float, ...]
    samples: int
    significant: bool

    def to_json(self) -> dict[str, Any]:
        """The tag's entry of ``diagnose --json``'s ``where``."""
        return {
            "offset": _num(self.offset), "trend": _num(self.trend), "noise": _num(self.noise),
            "rms": _num(self.rms), "lag_seconds": _num(self.lag_seconds),
            "lag_correlation": _num(self.lag_correlation),
            "conditions": {k: _num(v) for k, v in self.conditions.items()},
            "conditions_r2": _num(self.conditions_r2), "stoppage_rms": _num(self.stoppage_rms),
            "whiteness": _num(self.whiteness), "periods": [list(p) for p in self.periods],
            "samples": int(self.samples), "significant": bool(self.significant),
        }


def _num(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def characterise(tag: str, time: npt.ArrayLike, residual: npt.ArrayLike, sigma: float, *,
                 simulated: npt.ArrayLike | None = None, inputs: Mapping[str, npt.ArrayLike] | None = None,
                 after_stoppage: npt.ArrayLike | None = None, blocks: int = DEFAULT_BLOCKS) -> TagResidual:
    """Describe a residual series against its noise level.

    Parameters
    ----------
    tag
        Tag name (for the result).
    time
        Grid times (s).
    residual
        ``measured - simulated``; NaN where not scored.
    sigma
        The tag's noise standard deviation (:func:`noise_sigma` of the measured series).
    simulated
        The simulated output on the grid (for the lag structure), no NaN.
    inputs
        Input tag -> values on the grid (for the operating-condition regression).
    after_stoppage
        Boolean mask of the grid points in the settle periods after stoppages.
    blocks
        Number of periods the window is cut into.

    Returns
    -------
    TagResidual

    Examples
    --------
    >>> t = np.arange(0.0, 3600.0, 10.0)
    >>> res = characterise("TI", t, 0.5 + 0.0 * t, 0.1)
    >>> round(res.offset, 3), res.significant
    (0.5, True)
    """
    t = np.asarray(time, dtype=float)
    r = np.asarray(residual, dtype=float)
    ok = np.isfinite(r)
    n = int(ok.sum())
    edges = np.linspace(t[0], t[-1] + (t[1] - t[0] if t.size > 1 else 1.0), blocks + 1)
    if n < 3:
        return TagResidual(tag, sigma, math.nan, math.nan, math.nan, math.nan, math.nan, {}, math.nan,
                           math.nan, math.nan, (), tuple([math.nan] * blocks), tuple(map(float, edges)), n, False)
    tk, rk = t[ok], r[ok]
    rms = float(np.sqrt(np.mean(rk * rk)))
    offset = float(rk.mean())
    tc = (tk - tk.mean()) / 3600.0
    coef, _ = _lstsq([np.ones_like(tc), tc], rk)
    trend = float(coef[1])
    span_h = float(tk.max() - tk.min()) / 3600.0

    lag_seconds, lag_corr = math.nan, math.nan
    if simulated is not None:
        y = np.asarray(simulated, dtype=float)
        dy = np.gradient(y, t)[ok]
        dyc = dy - dy.mean()
        rc = rk - rk.mean()
        den = float(np.dot(dyc, dyc))
        if den > 0 and float(np.dot(rc, rc)) > 0:
            lag_seconds = float(-np.dot(rc, dyc) / den)
            lag_corr = float(-np.dot(rc, dyc) / math.sqrt(den * float(np.dot(rc, rc))))

    conditions: dict[str, float] = {}
    r2 = math.nan
    if inputs:
        cols, names = [np.ones(n)], []
        for name, values in inputs.items():
            u = np.asarray(values, dtype=float)[ok]
            sd = float(np.std(u))
            if np.all(np.isfinite(u)) and sd > 0:
                cols.append((u - u.mean()) / sd)
                names.append(name)
        if names:
            c, rest = _lstsq(cols, rk)
            conditions = {name: float(v) for name, v in zip(names, c[1:])}
            var = float(np.var(rk))
            r2 = float(1.0 - np.var(rest) / var) if var > 0 else 0.0

    stoppage_rms = math.nan
    if after_stoppage is not None:
        mask = np.asarray(after_stoppage, dtype=bool)[ok]
        if mask.any():
            stoppage_rms = float(np.sqrt(np.mean(rk[mask] ** 2)))

    means, periods = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (tk >= a) & (tk < b)
        m = float(rk[sel].mean() / sigma) if sel.sum() >= 2 and sigma > 0 else math.nan
        means.append(m)
        if math.isfinite(m) and abs(m) > PERIOD_THRESHOLD:
            periods.append((float(a), float(b)))
    merged: list[tuple[float, float]] = []
    for a, b in periods:
        if merged and abs(merged[-1][1] - a) < 1e-9:
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))

    significant = bool(sigma > 0 and (rms > RMS_THRESHOLD * sigma or abs(offset) > OFFSET_THRESHOLD * sigma
                                      or abs(trend) * span_h > OFFSET_THRESHOLD * sigma))
    return TagResidual(tag, float(sigma), rms, offset, trend, lag_seconds, lag_corr, conditions, r2,
                       stoppage_rms, ljung_box_lag1(rk), tuple(merged), tuple(means),
                       tuple(float(e) for e in edges), n, significant)


@dataclass(frozen=True)
class BalanceCheck:
    """A ``[[balances]]`` entry checked on the measurements.

    Attributes
    ----------
    name
        The balance's name.
    tags
        Its tags.
    imbalance
        Mean of the signed sum (units of the terms).
    noise
        Standard deviation the noise of its terms gives the sum (``sqrt(sum f**2 sigma**2)``).
    closes
        ``|imbalance| <= max(tolerance, 3 * noise / sqrt(n_eff))`` (the sum vanishes within noise).
    """

    name: str
    tags: tuple[str, ...]
    imbalance: float
    noise: float
    closes: bool

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "tags": list(self.tags), "imbalance": _num(self.imbalance),
                "noise": _num(self.noise), "closes": self.closes}


def check_balance(name: str, terms: Mapping[str, float], series: Mapping[str, npt.ArrayLike], *,
                  tolerance: float = 0.0) -> BalanceCheck:
    """Check that ``sum(factor * series[tag])`` vanishes within the noise of its terms.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> a = 2.0 + rng.normal(0, 0.01, 2000)
    >>> b = 2.0 + rng.normal(0, 0.01, 2000)
    >>> check_balance("m", {"a": 1.0, "b": -1.0}, {"a": a, "b": b}).closes
    True
    >>> check_balance("m", {"a": 1.0, "b": -1.0}, {"a": a, "b": b + 0.05}).closes
    False
    """
    total = None
    var = 0.0
    for tag, factor in terms.items():
        v = np.asarray(series[tag], dtype=float)
        total = factor * v if total is None else total + factor * v
        var += (factor * noise_sigma(v)) ** 2
    assert total is not None
    ok = np.isfinite(total)
    imbalance = float(np.mean(total[ok])) if ok.any() else math.nan
    noise = math.sqrt(var)
    # the terms' slow errors make the sum autocorrelated: count one independent sample per 10
    n_eff = max(1.0, ok.sum() / 10.0)
    closes = bool(abs(imbalance) <= max(tolerance, 3.0 * noise / math.sqrt(n_eff) + 1e-12))
    return BalanceCheck(name, tuple(terms), imbalance, noise, closes)


# --------------------------------------------------------------------------- from a spec


@dataclass(frozen=True)
class WindowResiduals:
    """The null model's outputs and residuals on one window (scored samples; lead-in cut off).

    Attributes
    ----------
    name
        ``"training"`` or ``"validation"``.
    time
        Grid times (s from the first sample).
    measured, simulated
        Output tag -> series (measured NaN where not scored).
    inputs
        Input tag -> measured input series.
    """

    name: str
    time: np.ndarray
    measured: dict[str, np.ndarray]
    simulated: dict[str, np.ndarray]
    inputs: dict[str, np.ndarray]

    def residual(self, tag: str) -> np.ndarray:
        """``measured - simulated`` of *tag* (NaN where not scored)."""
        return self.measured[tag] - self.simulated[tag]


@dataclass(frozen=True)
class WhereResult:
    """Where the null model and the measurements disagree.

    Attributes
    ----------
    null
        The null estimate (the spec's candidates fitted on training).
    tags
        Output tag -> :class:`TagResidual` on the training window.
    validation_tags
        Output tag -> :class:`TagResidual` on the validation window.
    balances
        The spec's balances checked on the measurements.
    training, validation
        The null model's series per window.
    noise
        Output tag -> the noise its residual is judged against: the sensor noise
        and the propagated input noise in quadrature.
    sensor_noise
        Output tag -> noise sigma of the measured series (:func:`noise_level`).
    propagated
        Output tag -> RMS change of the null model's output when the inputs carry a
        second, independent draw of their noise (:func:`propagated_noise`).
    """

    null: EstimationResult
    tags: dict[str, TagResidual]
    validation_tags: dict[str, TagResidual]
    balances: tuple[BalanceCheck, ...]
    training: WindowResiduals
    validation: WindowResiduals
    noise: dict[str, float]
    problem: Any = field(default=None, repr=False)
    windows: Any = field(default=None, repr=False)
    corrections: dict[str, float] = field(default_factory=dict)
    jacobian: tuple[dict[str, np.ndarray], dict[str, np.ndarray]] = field(default=({}, {}), repr=False)
    x: np.ndarray | None = field(default=None, repr=False)
    input_tags: dict[str, str] = field(default_factory=dict, repr=False)
    sensor_noise: dict[str, float] = field(default_factory=dict)
    propagated: dict[str, float] = field(default_factory=dict)
    varying: VaryingBasis | None = field(default=None, repr=False)
    held: tuple[str, ...] = ()

    @property
    def significant(self) -> list[str]:
        """Tags whose residual is significant on training or validation."""
        return [t for t in self.tags if self.tags[t].significant or self.validation_tags[t].significant]

    def to_json(self) -> dict[str, Any]:
        """``diagnose --json``'s ``where``: per tag, the training description plus the validation flag."""
        out = {}
        for tag, res in self.tags.items():
            doc = res.to_json()
            val = self.validation_tags[tag]
            doc["significant"] = bool(res.significant or val.significant)
            doc["validation"] = {"offset": _num(val.offset), "trend": _num(val.trend), "rms": _num(val.rms),
                                 "significant": bool(val.significant)}
            if tag in self.sensor_noise:
                doc["sensor_noise"] = _num(self.sensor_noise[tag])
                doc["input_noise"] = _num(self.propagated.get(tag, 0.0))
            if tag in self.corrections:
                doc["correction"] = _num(self.corrections[tag])
            out[tag] = doc
        return out


def window_series(problem: Problem, window: WindowData, x: npt.ArrayLike,
                  input_tags: Mapping[str, str], history: tuple[WindowData, ...] = ()) -> WindowResiduals:
    """Simulate *window* at parameters *x* and cut off the lead-in (*history*: the windows whose runs a
    carried state comes from, :func:`trackingbox.simulation.windows.carried_states`)."""
    sim = simulate_window(problem, window, x, history=history)
    keep = slice(window.lead, None)
    by_fmu = {fmu: tag for tag, fmu in input_tags.items()}
    return WindowResiduals(
        window.name, np.asarray(window.time[keep], dtype=float),
        {tag: np.asarray(v[keep], dtype=float) for tag, v in window.measured.items()},
        {tag: np.asarray(v[keep], dtype=float) for tag, v in sim.items()},
        {by_fmu.get(k, k): np.asarray(v[keep], dtype=float) for k, v in window.inputs.items()},
    )


def where(spec: Spec, *, null: EstimationResult | None = None, estimate_options: Mapping[str, Any] | None = None,
          blocks: int = DEFAULT_BLOCKS, varying_step: float | None = None) -> WhereResult:
    """Fit the null model (unless given) and describe every output tag's residual.

    Parameters
    ----------
    spec
        A loaded spec.
    null
        An existing estimate of the spec's candidates on its training window (skips
        the estimation).
    estimate_options
        Keyword arguments for :func:`trackingbox.estimation.estimate`.
    blocks
        Periods per window for the heat map.
    varying_step
        Knot spacing (s) of the spec's ``[diagnose] varying`` candidates in the null model
        (:func:`trackingbox.diagnose.varying.basis_for`; default the spec's ``[pairing] closed_loop``).

    Returns
    -------
    WhereResult
    """
    options = dict(estimate_options or {})
    if null is None:
        log.info("fitting the null model (the spec's %d candidate parameters)", len(spec.parameters))
        null = estimate(spec, **options)
    problem = problem_from_spec(spec, warmup=options.get("warmup"))
    training, validation = load_windows(spec, warmup=problem.warmup)
    x = np.array([null.parameters.get(n, s) for n, s in zip(problem.names, problem.start)])
    balance_tags = [t for b in getattr(spec, "balances", ()) or () for t in b.terms]
    view = MeasurementView.from_spec(spec, "all", tags=balance_tags)
    sensor = {tag: noise_level(view.values(tag)) for tag in spec.outputs}
    after = _after_stoppage(view)
    try:
        series, jac = series_and_jacobian(problem, (training, validation), x, spec.inputs)
        propagated = propagated_noise(problem, (training, validation), x, spec.inputs, series)
    finally:
        close_models()
    noise = {tag: math.hypot(sensor[tag], propagated.get(tag, 0.0)) for tag in spec.outputs}
    basis = basis_for(spec, problem, series[0].time, series[1].time, varying_step)
    held = tuple(t for t in spec.outputs if view.method.get(t) == "hold")
    raw = series
    series, delta0 = polish(raw, jac, noise, step_bounds(problem, x), basis, x)
    for _ in range(2 if held else 0):
        # an exception-reported tag held on the grid: its noise is the fast part of the residual
        # (sensor noise, the held value's distance from the truth), measured, then the null polished again
        for tag in held:
            floor = held_noise(series, tag, problem.sample_time)
            if math.isfinite(floor) and floor > 0:
                sensor[tag] = floor
                noise[tag] = max(floor, math.hypot(noise_level(view.values(tag)), propagated.get(tag, 0.0)))
        series, delta0 = polish(raw, jac, noise, step_bounds(problem, x), basis, x)
    described = []
    for s in series:
        idx = np.searchsorted(view.grid, s.time)
        idx = np.clip(idx, 0, view.grid.size - 1)
        described.append({
            tag: characterise(tag, s.time, s.residual(tag), noise[tag], simulated=s.simulated[tag],
                              inputs=s.inputs, after_stoppage=after[idx] if after is not None else None,
                              blocks=blocks)
            for tag in spec.outputs})
    balances = tuple(
        check_balance(b.name, b.terms, {t: view.values(t) for t in b.terms}, tolerance=b.tolerance)
        for b in getattr(spec, "balances", ()) or ())
    corrections = {}
    for state in spec.states:
        if state.tag in spec.outputs:
            r = series[0].residual(state.tag)
            corrections[state.tag] = float(state.gain * np.nanmean(r))
    for tag, res in described[0].items():
        log.info("%s: noise %.3g (sensor %.3g, inputs %.3g), rms %.3g, offset %.3g, trend %.3g/h%s", tag,
                 res.noise, sensor[tag], propagated.get(tag, 0.0), res.rms, res.offset, res.trend,
                 " (significant)" if res.significant else "")
    return WhereResult(null, described[0], described[1], balances, series[0], series[1], noise, problem,
                       (training, validation), corrections, (jac[0], jac[1]), x + delta0 if delta0.size else x,
                       dict(spec.inputs), sensor, propagated, basis, held)


def held_noise(series: Sequence[WindowResiduals], tag: str, sample_time: float) -> float:
    """The noise of an exception-reported tag laid on the grid by sample-and-hold: the residual's floor.

    A historian archives such a tag only when it leaves its dead band (or at its heartbeat),
    so on the grid it is a staircase: the second differences that :func:`noise_sigma` reads
    are mostly zero and its estimate collapses (on the evaporator's flash pressure PI-6151,
    1.2 Pa against 200 Pa of sensor noise and a 300 Pa dead band). What a perfect twin would
    leave in such a tag is the sensor noise plus the held value's distance from the truth,
    both faster than the half hour the pairing's noise floor averages over: the spread of
    the null model's residual around its own moving average over that span
    (:func:`trackingbox.analysis.offsets.noise_floor`), pooled over the windows. The
    residual rather than the series, so the process's own moves within the span (a
    controller's swing, an operator's ramp) are not counted as noise.
    """
    values = []
    for s in series:
        r = s.residual(tag)
        f = noise_floor(r, sample_time)
        if math.isfinite(f):
            values.append((f, int(np.isfinite(r).sum())))
    if not values:
        return math.nan
    total = sum(n for _, n in values)
    return math.sqrt(sum(f * f * n for f, n in values) / max(total, 1))


def relinearised(result: WhereResult, delta: np.ndarray) -> WhereResult:
    """*result* with its series and Jacobian simulated again at ``x + delta`` (clipped to the bounds).

    One Gauss-Newton step of a joint fit (:func:`trackingbox.diagnose.screen.joint`)
    moves the candidates by *delta*; re-linearising there removes the error of the
    first linearisation when the move is large (a bias absorbed into a coefficient).
    """
    problem = result.problem
    x1 = np.clip(np.asarray(result.x, dtype=float) + delta, problem.lower, problem.upper)
    try:
        series, jac = series_and_jacobian(problem, result.windows, x1, result.input_tags)
    finally:
        close_models()
    return replace(result, training=series[0], validation=series[1], jacobian=(jac[0], jac[1]), x=x1)


def input_noise(window: Any) -> dict[str, float]:
    """FMU input -> noise sigma of its values on *window* (:func:`noise_sigma`; 0 where it cannot be told).

    No resolution floor here (unlike :func:`noise_level`): an input that carries no
    noise (a set point, a held valve position) is not perturbed.

    >>> from types import SimpleNamespace
    >>> rng = np.random.default_rng(1)
    >>> w = SimpleNamespace(inputs={"u": 5.0 + rng.normal(0.0, 0.3, 4000), "sp": np.full(4000, 2.0)})
    >>> {k: round(v, 1) for k, v in input_noise(w).items()}
    {'u': 0.3, 'sp': 0.0}
    """
    out = {}
    for name, values in window.inputs.items():
        sigma = noise_sigma(values)
        out[name] = sigma if math.isfinite(sigma) and sigma > 0 else 0.0
    return out


def perturbed(window: Any, sigma: Mapping[str, float], seed: int = PROPAGATION_SEED) -> Any:
    """*window* with every input moved by an independent normal draw of standard deviation ``sigma[input]``."""
    rng = np.random.default_rng(seed)
    inputs = {}
    for name in sorted(window.inputs):
        v = np.asarray(window.inputs[name], dtype=float)
        s = float(sigma.get(name, 0.0))
        inputs[name] = v + rng.normal(0.0, s, v.shape) if s > 0 else v
    return replace(window, inputs=inputs)


def propagated_noise(problem: Any, windows: Sequence[Any], x: npt.ArrayLike, input_tags: Mapping[str, str],
                     series: Sequence[WindowResiduals]) -> dict[str, float]:
    """Output tag -> the spread the inputs' own noise causes in the null model's output.

    The twin runs on the measured inputs, noise included; the plant ran on the true
    ones. Running the twin again with the inputs moved by a second, independent draw
    of their noise (each input's sigma estimated on the training window,
    :func:`input_noise`) changes every output by about what the first draw did:
    the RMS of that change over the scored samples of all *windows* (pooled) is the
    tag's propagated noise. One run per window, in one batch (:mod:`.parallel`).
    """
    if not windows:
        return {}
    sigma = input_noise(windows[0])
    if not any(s > 0 for s in sigma.values()):
        return {tag: 0.0 for tag in series[0].simulated}
    calls = [(problem, perturbed(w, sigma, PROPAGATION_SEED + k), x, input_tags) for k, w in enumerate(windows)]
    runs = map_calls(window_series, calls)
    out = {}
    for tag in series[0].simulated:
        sq, n = 0.0, 0
        for base, moved in zip(series, runs):
            d = moved.simulated[tag] - base.simulated[tag]
            d = d[np.isfinite(base.measured[tag]) & np.isfinite(d)]
            sq += float(np.dot(d, d))
            n += d.size
        out[tag] = math.sqrt(sq / n) if n else 0.0
    for tag, value in out.items():
        log.debug("%s: propagated input noise %.3g", tag, value)
    return out


def series_and_jacobian(problem: Any, windows: Sequence[Any], x: npt.ArrayLike, input_tags: Mapping[str, str],
                        step: float = 1.0e-3) -> tuple[list[WindowResiduals], list[dict[str, np.ndarray]]]:
    """The series at *x* on each window and its output Jacobian (:func:`output_jacobian`), in one batch of runs.

    The ``(1 + p)`` runs per window are independent; inside
    :func:`trackingbox.diagnose.parallel.pool` they spread over its workers. The
    arithmetic is :func:`output_jacobian`'s, so the result is the same either way.
    """
    x = np.asarray(x, dtype=float)
    points, h = jacobian_points(x, problem.lower, problem.upper, step)
    calls = [(problem, w, p, input_tags) for w in windows for p in (x, *points)]
    runs = map_calls(window_series, calls)
    series, jac = [], []
    per = 1 + len(points)
    for k in range(len(windows)):
        base, moved = runs[k * per], runs[k * per + 1: (k + 1) * per]
        series.append(base)
        jac.append({tag: (np.column_stack([(m.simulated[tag] - base.simulated[tag]) / hj for m, hj in zip(moved, h)])
                          if len(moved) else np.zeros((base.time.size, 0)))
                    for tag in base.simulated})
    return series, jac


def output_jacobian(problem: Any, window: Any, x: npt.ArrayLike, input_tags: Mapping[str, str],
                    base: WindowResiduals, step: float = 1.0e-3) -> dict[str, np.ndarray]:
    """Tag -> ``(n, p)`` sensitivity of the simulated output to the spec's candidates (forward differences).

    The step is *step* times each bound range, backwards at the upper bound
    (:func:`trackingbox.estimation.jacobian_points`).
    """
    points, h = jacobian_points(x, problem.lower, problem.upper, step)
    cols: dict[str, list[np.ndarray]] = {tag: [] for tag in base.simulated}
    for point, hj in zip(points, h):
        sim = window_series(problem, window, point, input_tags).simulated
        for tag in cols:
            cols[tag].append((sim[tag] - base.simulated[tag]) / hj)
    return {tag: np.column_stack(c) if c else np.zeros((base.time.size, 0)) for tag, c in cols.items()}


def polish(series: Sequence[WindowResiduals], jac: Sequence[Mapping[str, np.ndarray]],
           noise: Mapping[str, float], bounds: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
           varying: VaryingBasis | None = None, x: npt.ArrayLike | None = None,
           ) -> tuple[list[WindowResiduals], np.ndarray]:
    """The null model (and the step taken) moved by one linearised step to the noise-weighted least-squares optimum.

    The estimate minimises the mean NRMSE (tags weighted by their range); the
    screening scores candidates by residuals weighted by the noise. Moving the
    null to the noise-weighted optimum first (one Gauss-Newton step with the
    training Jacobian, applied to both windows) means a candidate's gain is never
    just that reweighting. *bounds* (:func:`step_bounds`) keep the step inside the candidates'
    bounds: the null model is the twin with its parameters where the spec allows them (a twin
    that misses more than a parameter error, heat production's linear laws against a quadratic
    plant, pins candidates at their bounds, and a free step took HEX300.kht from its lower bound
    850 to 690, where the ramps of the screening were then simulated).
    """
    train, valid = series
    if varying is None:
        delta = joint_lstsq({t: train.residual(t) for t in train.simulated}, jac[0], noise, bounds)
        if delta.size == 0:
            return list(series), delta
        out = []
        for s, j in zip(series, jac):
            sim = {t: v + j[t] @ delta for t, v in s.simulated.items()}
            out.append(WindowResiduals(s.name, s.time, s.measured, sim, s.inputs))
        return out, delta
    # with varying candidates: the simulated series move by the fitted step and trajectories
    fit = fit_windows({t: train.residual(t) for t in train.simulated}, {t: valid.residual(t) for t in valid.simulated},
                      (jac[0], jac[1]), noise, bounds=bounds, varying=varying, x=x)
    out = []
    for s, j, u, which in ((train, jac[0], fit.varying_train, "train"), (valid, jac[1], fit.varying_valid, "valid")):
        v = varying.columns(j, which, list(s.simulated), {t: s.time.size for t in s.simulated})
        sim = {t: y + j[t] @ fit.delta + (v[t] @ u if u.size else 0.0) for t, y in s.simulated.items()}
        out.append(WindowResiduals(s.name, s.time, s.measured, sim, s.inputs))
    return out, fit.delta


def _after_stoppage(view: Any) -> np.ndarray | None:
    """Grid points in the hour after each stoppage ends (None without stoppages)."""
    stopped = np.asarray(view.stopped, dtype=bool)
    if not stopped.any():
        return None
    out = np.zeros_like(stopped)
    ends = np.flatnonzero(stopped[:-1] & ~stopped[1:]) + 1
    width = int(round(3600.0 / view.sample_time))
    for e in ends:
        out[e:e + width] = True
    return out & ~stopped


def heatmap_matrix(result: WhereResult) -> tuple[list[str], list[str], np.ndarray]:
    """Rows (tags), columns (period labels, hours from the first sample) and values for the heat map.

    The values are the block means of the normalised residual ``r / sigma`` over the
    training then the validation window.
    """
    tags = list(result.tags)
    cols: list[str] = []
    rows = []
    for described in (result.tags, result.validation_tags):
        first = described[tags[0]]
        edges = first.block_edges
        cols += [f"{a / 3600:.1f}-{b / 3600:.1f} h" for a, b in zip(edges[:-1], edges[1:])]
    for tag in tags:
        rows.append(list(result.tags[tag].blocks) + list(result.validation_tags[tag].blocks))
    return tags, cols, np.array(rows, dtype=float)
