"""The live run's windowed measurements against the whole view of the same samples (no server, no FMU).

The reference is :meth:`MeasurementView.from_spec` reading the samples as a
historian's long export: the windows the live stream hands the tracking loop
(fed sample by sample, grown batch by batch, pruned behind the loop) must be
that view's rows, array for array: the tags' values (linear and
sample-and-hold, gaps, bad-quality events), the stoppage and input-gap masks,
the twin's input table and the scored points.
"""
from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np
import pytest

from trackingbox.data import MeasurementView
from trackingbox.online.livestream import EXACT_INTERVALS, LiveMeasurements, _Intervals
from trackingbox.spec import DataRules, Spec, StoppageRule, TrackingSettings

ORIGIN = dt.datetime(2026, 3, 1, 6, 0, tzinfo=dt.timezone.utc)


def _records(seed: int, end: float) -> list[tuple[str, float, float]]:
    """(tag, s, value or NaN) of three tags: u (exception-reported), y (irregular), z (the stoppage tag)."""
    rng = np.random.default_rng(seed)
    out = []
    t = 0.0
    while t < end:  # u: reported on change, at the latest every heartbeat (60 s)
        out.append(("u", t, float(np.round(rng.normal(5.0, 1.0), 1))))
        t += float(rng.uniform(3.0, 60.0))
    t = 0.4
    while t < end:  # y: every ~10 s with jitter, two dropped stretches
        if not (3000.0 < t < 3100.0 or 7000.0 < t < 7400.0):
            out.append(("y", t, float(np.sin(t / 900.0) + rng.normal(0, 0.01))))
        t += float(rng.uniform(8.0, 12.0))
    t = 1.1
    while t < end:  # z: a flow, stopped from 4000 s to 4600 s
        out.append(("z", t, 0.1 if 4000.0 <= t < 4600.0 else 2.0 + rng.normal(0, 0.05)))
        t += float(rng.uniform(5.0, 15.0))
    for tag, a, b in (("y", 5200.0, 5320.0), ("u", 6100.0, 6200.0), ("z", 8000.0, 8030.0)):  # bad quality
        out = [(k, s, np.nan if (k == tag and a <= s < b) else v) for k, s, v in out]
    out.append(("y", 5250.0, np.nan))
    return sorted(out, key=lambda r: r[1])


def _spec(tmp_path: Path, records: list[tuple[str, float, float]]) -> Spec:
    path = tmp_path / "m.csv"
    lines = ["tag,time,value"]
    for tag, s, v in records:
        stamp = (ORIGIN + dt.timedelta(microseconds=round(s * 1e6))).isoformat()
        lines.append(f"{tag},{stamp},{'' if np.isnan(v) else repr(v)}")
    path.write_text("\n".join(lines) + "\n")
    return Spec(path=tmp_path / "s.toml", twin=tmp_path / "t.fmu", measurements=path, sample_time=10.0,
                inputs={"u": "u_in"}, outputs={"y": "y_out", "z": "z_out"},
                data=DataRules(stoppage=StoppageRule("z", below=0.5, settle=120.0), heartbeat={"u": 60.0}),
                tracking=TrackingSettings(hold_until=300.0))


def _same(part: MeasurementView, whole: MeasurementView, a: int) -> None:
    n = part.grid.size
    np.testing.assert_array_equal(part.grid, whole.grid[a:a + n])
    for tag in ("u", "y", "z"):
        np.testing.assert_array_equal(part.samples[tag], whole.samples[tag][a:a + n], err_msg=tag)
    np.testing.assert_array_equal(part.stopped, whole.stopped[a:a + n])
    np.testing.assert_array_equal(part.input_gap, whole.input_gap[a:a + n])
    np.testing.assert_array_equal(part.inputs["u_in"].to_numpy(), whole.inputs["u_in"].to_numpy()[a:a + n])
    for tag in ("y", "z"):
        np.testing.assert_array_equal(part.scored[tag], whole.scored[tag][a:a + n], err_msg=tag)


@pytest.mark.parametrize("seed", [0, 1])
def test_windows_are_the_whole_views_rows(tmp_path: Path, seed: int) -> None:
    end = 10000.0
    records = _records(seed, end)
    spec = _spec(tmp_path, records)
    whole = MeasurementView.from_spec(spec, "all", skip=300.0)
    assert whole.stopped.any() and np.isnan(whole.samples["y"]).any() and whole.input_gap.any()
    assert whole.max_gap["u"] == 90.0  # the heartbeat rule
    live = LiveMeasurements(spec, spec.measurements, skip=300.0, rows_per_window=150)
    fed, k = 0, 0
    # batches as the tracker makes them: rows up to the last sample every tag has reached, the loop
    # at row k asking for windows from k - 1, the samples behind it dropped
    for clock in np.arange(600.0, end, 437.0):
        while fed < len(records) and records[fed][1] <= clock:
            tag, s, v = records[fed]
            stamp = ORIGIN + dt.timedelta(microseconds=round(s * 1e6))  # as the tracker gets it
            live.add(tag, (stamp - ORIGIN).total_seconds(), v)
            fed += 1
        last = {tag: max(s for t, s, _ in records[:fed] if t == tag) for tag in "uyz"}
        ready = int(np.floor(min(last.values()) / 10.0 + 1e-9))
        live.grow(ready + 1)
        while k < ready - 1:
            a = max(0, k - 1)
            b = min(live.n_rows, a + 154)
            _same(live.view(a, b), whole, a)
            k = ready - 1 if b == live.n_rows else b - 4  # a window reaches 4 rows past those run in it
        live.prune(k)
    # the gap rule of y: 2.5 x its median interval, counted as the samples came (the whole file's at the end)
    for tag, s, v in records[fed:]:
        live.add(tag, (ORIGIN + dt.timedelta(microseconds=round(s * 1e6)) - ORIGIN).total_seconds(), v)
    assert live.max_gap["y"] == pytest.approx(whole.max_gap["y"])
    assert live.held < len(records) / 3  # what the loop left behind was dropped
    with pytest.raises(Exception, match="no longer hold row"):
        live.view(0, 10)


def test_interval_counts_stay_bounded_and_give_the_median() -> None:
    # a historian's irregular timestamps: nearly every interval its own value
    x = np.random.default_rng(1).lognormal(np.log(10.0), 0.5, 200_000)
    few = _Intervals()
    for v in x[:5001]:
        few.add(float(v))
    assert not few.coarse and few.median() == np.median(x[:5001])  # exact below the limit
    many = _Intervals()
    sizes = []
    for i, v in enumerate(x):
        many.add(float(v))
        if i % 10_000 == 0:
            sizes.append(len(many.counts))
    decades = int(np.ceil(np.log10(x.max())) - np.floor(np.log10(x.min())))
    assert many.coarse and max(sizes) <= EXACT_INTERVALS + 1 and len(many.counts) <= 9000 * decades
    assert many.median() == pytest.approx(np.median(x), rel=5e-4)  # 4 significant digits
