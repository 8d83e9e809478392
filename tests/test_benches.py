"""Bench cases: scenario building blocks, written files, sensor noise, --set, CLI errors."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trackingbox.benches import scenario as sc

# --------------------------------------------------------------------------- scenario parts (fast)


def test_moves_start_at_base_and_stay_in_range():
    t = np.arange(0.0, 8 * 3600.0 + 1, 10.0)
    rng = np.random.default_rng(1)
    y = sc.moves(t, rng, base=1.0, low=0.7, high=1.3, mean_interval=1800.0, hold_start=900.0)
    assert np.all(y[t < 900.0] == 1.0)
    assert y.min() >= 0.7 - 1e-12 and y.max() <= 1.3 + 1e-12
    # with a mean interval of 30 min over 8 h there are changes (steps and ramps)
    changes = np.count_nonzero(np.abs(np.diff(y)) > 1e-12)
    assert changes > 5


def test_drift_is_bounded_random_walk_with_requested_spread():
    # Ornstein-Uhlenbeck: stationary std = sigma; long run average over many correlation times
    t = np.arange(0.0, 2000 * 3600.0, 60.0)
    y = sc.drift(t, np.random.default_rng(2), sigma=0.5, time_constant=3600.0)
    assert y[0] == 0.0
    assert abs(y.std() - 0.5) < 0.05
    # correlation after one time constant is exp(-1)
    lag = 60
    r = np.corrcoef(y[:-lag], y[lag:])[0, 1]
    assert abs(r - math.exp(-1.0)) < 0.05


def test_daily_profile_peaks_morning_and_evening():
    t = np.arange(0.0, 24 * 3600.0, 60.0)
    p = sc.daily_profile(t)
    hour = t / 3600.0
    assert 0.0 <= p.min() and p.max() <= 1.0
    assert p[(hour > 0.5) & (hour < 3)].max() < 0.25          # night is low
    morning = hour[(hour > 4) & (hour < 10)][np.argmax(p[(hour > 4) & (hour < 10)])]
    evening = hour[(hour > 16) & (hour < 22)][np.argmax(p[(hour > 16) & (hour < 22)])]
    assert abs(morning - 7.0) < 0.5 and abs(evening - 19.0) < 0.75
    # periodic: the next day repeats
    assert np.allclose(sc.daily_profile(t + 86400.0), p)
