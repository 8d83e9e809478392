"""The heat-production bench's estimation yardstick (``scripts/_bench_heat_production.py``) by hand."""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from trackingbox.benches.base import Sensor

_SPEC = importlib.util.spec_from_file_location(
    "_bench_heat_production", Path(__file__).resolve().parents[1] / "scripts" / "_bench_heat_production.py")
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)


def test_share_of_the_removable_error_by_hand() -> None:
    initial = {"A": 0.30, "B": 0.10, "C": 0.02, "D": 0.05}
    truth = {"A": 0.10, "B": 0.04, "C": 0.019, "D": 0.06}
    estimated = {"A": 0.14, "B": 0.07, "C": 0.010, "D": 0.01}
    floor = {"A": 0.01, "B": 0.01, "C": 0.015, "D": 0.005}
    share, counted, left = bench.judge(initial, estimated, truth, floor)
    # C: 0.02 is within 2 x its floor 0.015; D: the truth does not lower it. A and B:
    # removed (0.30 - 0.14) + (0.10 - 0.07) = 0.19 of removable (0.30 - 0.10) + (0.10 - 0.04) = 0.26
    assert counted == ["A", "B"]
    assert [t for t, _ in left] == ["C", "D"]
    assert share == pytest.approx(0.19 / 0.26)
    assert share >= bench.MIN_SHARE
    # an estimate that makes a counted tag worse than it started counts against the share
    share2, _, _ = bench.judge(initial, {**estimated, "B": 0.15}, truth, floor)
    assert share2 == pytest.approx((0.16 - 0.05) / 0.26) and share2 < bench.MIN_SHARE
    # nothing removable: no share (the benchmark then fails rather than passing on nothing)
    assert math.isnan(bench.judge({"A": 0.01}, {"A": 0.01}, {"A": 0.01}, {"A": 0.01})[0])


def test_noise_floor_is_the_sensor_noise_over_the_range() -> None:
    t = np.linspace(0.0, 1.0, 101)
    temp = 330.0 + 4.0 * t  # a 4 K range; temperature noise 0.1 K
    assert bench.noise_floor(Sensor("TI-1", "x", "x", "temperature"), temp) == pytest.approx(0.1 / 4.0)
    flow = 0.05 + 0.01 * t   # 1 % of the reading (its RMS), over a 0.01 kg/s range
    rms = float(np.sqrt(np.mean(flow ** 2)))
    assert bench.noise_floor(Sensor("FI-1", "x", "x", "flow"), flow) == pytest.approx(0.01 * rms / 0.01)
    assert bench.noise_floor(Sensor("SI-1", "x", "x", "other"), flow) == 0.0  # DCS outputs: exact
