"""Building blocks for bench scenarios: operating-point changes, drifts, daily profiles.

Every function takes the sample times (s) and a seeded :class:`numpy.random.Generator`
and returns an array of the same length, so a scenario is a sum of reproducible parts.
"""
from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def moves(t: FloatArray, rng: np.random.Generator, *, base: float, low: float, high: float,
          mean_interval: float, ramp_fraction: float = 0.4, ramp_duration: tuple[float, float] = (300.0, 1800.0),
          hold_start: float = 900.0) -> FloatArray:
    """Operating-point changes: steps and ramps between random levels.

    Starts at *base*; after *hold_start* seconds, changes happen at exponentially
    distributed intervals (mean *mean_interval*). Each change goes to a new level
    drawn uniformly in [*low*, *high*], as a step or (with probability
    *ramp_fraction*) as a linear ramp lasting a random time in *ramp_duration*.

    Parameters
    ----------
    t : array of float
        Sample times in s, increasing.
    rng : numpy.random.Generator
    base, low, high : float
        Initial level and the range new levels are drawn from.
    mean_interval : float
        Mean time between changes, s.

    Returns
    -------
    array of float
    """
    y = np.full_like(t, base, dtype=float)
    level = base
    when = t[0] + hold_start + rng.exponential(mean_interval)
    while when < t[-1]:
        target = rng.uniform(low, high)
        if rng.random() < ramp_fraction:
            duration = rng.uniform(*ramp_duration)
            frac = np.clip((t - when) / duration, 0.0, 1.0)
            seg = t >= when
            y[seg] = level + (target - level) * frac[seg]
            when += duration
        else:
            y[t >= when] = target
        level = target
        when += rng.exponential(mean_interval)
    return y


def drift(t: FloatArray, rng: np.random.Generator, *, sigma: float, time_constant: float) -> FloatArray:
    """A slow random walk that stays bounded: Ornstein-Uhlenbeck noise.

    Stationary standard deviation *sigma*, correlation time *time_constant* (s),
    starting at 0.
    """
    y = np.zeros_like(t, dtype=float)
    if len(t) < 2 or sigma == 0.0:
        return y
    dt = np.diff(t)
    a = np.exp(-dt / time_constant)
    shocks = rng.standard_normal(len(dt)) * sigma * np.sqrt(1.0 - a * a)
    for i in range(1, len(t)):
        y[i] = a[i - 1] * y[i - 1] + shocks[i - 1]
    return y


def daily_profile(t: FloatArray, *, t0_hour: float = 0.0) -> FloatArray:
    """Typical daily heat-demand shape in [0, 1]: low at night, peaks at 07:00 and 19:00.

    A sum of two Gaussian bumps on a night base, periodic over 24 h; *t0_hour* is
    the clock hour at ``t = 0``.
    """
    hour = (t / 3600.0 + t0_hour) % 24.0

    def bump(center: float, width: float) -> FloatArray:
        d = (hour - center + 12.0) % 24.0 - 12.0
        return np.exp(-0.5 * (d / width) ** 2)

    shape = 0.15 + 0.85 * bump(7.0, 1.8) + 0.65 * bump(19.0, 2.5) + 0.3 * bump(13.0, 3.0)
    return np.clip(shape / 1.15, 0.0, 1.0)


def smooth(y: FloatArray, samples: int) -> FloatArray:
    """Moving average over *samples* samples (edges use the available samples)."""
    if samples <= 1:
        return y
    kernel = np.ones(samples) / samples
    padded = np.concatenate([np.full(samples // 2, y[0]), y, np.full(samples - 1 - samples // 2, y[-1])])
    return np.convolve(padded, kernel, mode="valid")
