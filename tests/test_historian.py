"""DCS-like historian export (``trackingbox.benches.historian``): the archive rules checked against
what a historian must have logged for frames whose values are known in closed form, and the
export read back by the data layer."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from trackingbox.benches.historian import HistorianSettings, TagSettings, export_history
from trackingbox.data import MeasurementView, read_table
from trackingbox.errors import DataError, SpecError
from trackingbox.spec import DataRules, Spec

DAY = 86400.0


def _frame(t, **columns):
    return pd.DataFrame({"time": t, **columns})


def test_dead_band_and_heartbeat_by_hand():
    # a ramp of 0.01 per s for 100 s, then steady; scan 10 s, no jitter, dead band 0.25, heartbeat 300 s
    t = np.arange(0.0, 1001.0)
    y = np.minimum(t, 100.0) * 0.01
    s = HistorianSettings(default=TagSettings(scan=10.0, jitter=0.0, deadband=0.25, heartbeat=300.0, phase=0.0),
                          outages_per_day=0.0)
    rec = export_history(_frame(t, y=y), s).records
    # by hand: the first scan; then each scan more than 0.25 away from the last archived value
    # (0 -> 0.3 at 30 s -> 0.6 at 60 s -> 0.9 at 90 s), the steady 1.0 at 100 s (0.1 away: no),
    # heartbeats 300 s after the last archived value: 390, 690, 990 s
    assert rec["time"].tolist() == [0.0, 30.0, 60.0, 90.0, 390.0, 690.0, 990.0]
    np.testing.assert_allclose(rec["value"], [0.0, 0.3, 0.6, 0.9, 1.0, 1.0, 1.0])


def test_every_archived_value_leaves_the_dead_band_or_is_a_heartbeat():
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 6 * 3600.0, 1.0)
    y = 50.0 + np.cumsum(rng.normal(0.0, 0.02, t.size))  # a random walk
    tag = TagSettings(scan=5.0, jitter=0.3, deadband=0.5, heartbeat=600.0)
    rec = export_history(_frame(t, y=y), HistorianSettings(default=tag, outages_per_day=0.0, seed=1)).records
    tt, v = rec["time"].to_numpy(), rec["value"].to_numpy()
    d = np.diff(tt)
    moved = np.abs(np.diff(v)) > 0.5
    # no silence longer than the heartbeat plus one scan with jitter
    assert d.max() <= 600.0 + 5.0 * (1 + 2 * 0.3) + 1e-6
    # a record that did not leave the dead band came because the heartbeat was due
    assert np.all(d[~moved] >= 600.0 - 1e-6)
    # and between two records no scan left the band: the frame stays within 0.5 + one scan's move of the
    # last archived value (the frame moves at most ~0.1 per 5 s here)
    held = np.interp(t, tt, v, left=np.nan)
    prev = v[np.searchsorted(tt, t, side="right") - 1]
    assert np.nanmax(np.abs(y[t >= tt[0]] - prev[t >= tt[0]])) < 0.5 + 0.25
    assert np.isfinite(held[t >= tt[0]]).all()


def test_scan_times_jitter_and_values_at_the_jittered_times():
    t = np.arange(0.0, 3601.0, 0.5)
    y = 2.0 + 0.001 * t  # linear: the archived value must be exactly 2 + 0.001 * (its own time)
    tag = TagSettings(scan=20.0, jitter=0.25, deadband=0.0, heartbeat=900.0)
    rec = export_history(_frame(t, y=y), HistorianSettings(default=tag, outages_per_day=0.0, seed=3)).records
    tt = rec["time"].to_numpy()
    assert np.all(np.diff(tt) > 0)
    # every scan archived (dead band 0): intervals within scan +- 2 x jitter x scan, not all equal
    d = np.diff(tt)
    assert d.min() >= 20.0 * (1 - 2 * 0.25) - 1e-9 and d.max() <= 20.0 * (1 + 2 * 0.25) + 1e-9
    assert d.std() > 1.0
    # timestamps on a millisecond grid, near k * scan + phase
    np.testing.assert_allclose(tt * 1000, np.round(tt * 1000), atol=1e-6)
    k = np.round((tt - tt[0]) / 20.0)
    assert np.abs(tt - tt[0] - 20.0 * k).max() <= 2 * 0.25 * 20.0 + 1e-9
    np.testing.assert_allclose(rec["value"], 2.0 + 0.001 * tt, rtol=0, atol=1e-12)


def test_communication_losses():
    t = np.arange(0.0, 2 * DAY, 2.0)
    frame = _frame(t, FI=5.0 + 0.0 * t, TI=80.0 + 0.0 * t)
    tag = TagSettings(scan=2.0, jitter=0.2, deadband=0.1, heartbeat=600.0)
    s = HistorianSettings(default=tag, outages_per_day=4.0, outage_duration=(600.0, 1800.0), seed=11)
    h = export_history(frame, s)
    assert h.outages, "four a day on average over two days: none drawn would be a bug"
    for o in h.outages:
        assert 600.0 - 1e-9 <= o.stop - o.start <= 1800.0 + 1e-9 or o.stop == t[-1]
        for tag_name in o.tags:
            rec = h.records[h.records["tag"] == tag_name]
            tt, v = rec["time"].to_numpy(), rec["value"].to_numpy()
            inside = (tt >= o.start) & (tt < o.stop)
            # one bad-quality event (NaN), the first scan of the loss, nothing else inside
            assert np.isnan(v[inside]).sum() == 1 and inside.sum() == 1
            assert tt[inside][0] - o.start <= 2.0 * 1.4 + 1e-9
            # the first scan after the loss is archived although the value did not move
            after = tt[tt >= o.stop]
            if after.size and o.stop < t[-1] - 10:
                assert after[0] - o.stop <= 2.0 * 1.4 + 1e-9
    # tags an outage does not take keep their heartbeat
    for tag_name in ("FI", "TI"):
        rec = h.records[h.records["tag"] == tag_name]
        good = rec["time"].to_numpy()[np.isfinite(rec["value"].to_numpy())]
        spans = [(o.start, o.stop) for o in h.outages if tag_name in o.tags]
        d = np.diff(good)
        starts = good[:-1]
        lost = np.array([any(a - 700 <= s0 < b for a, b in spans) for s0 in starts], dtype=bool)
        assert d[~lost].max() <= 600.0 + 2.0 * 1.4 + 1e-6


def test_same_seed_same_export_other_seed_other_export():
    t = np.arange(0.0, DAY, 1.0)
    frame = _frame(t, FI=5.0 + np.sin(t / 700.0), TI=80.0 + np.cos(t / 900.0))
    s = HistorianSettings(default=TagSettings(scan=3.0, deadband=0.01, heartbeat=600.0), seed=5)
    a, b = export_history(frame, s), export_history(frame, s)
    pd.testing.assert_frame_equal(a.records, b.records)
    assert a.outages == b.outages
    c = export_history(frame, HistorianSettings(default=s.default, seed=6))
    assert not a.records["time"].equals(c.records["time"])


def test_written_exports_read_back(tmp_path):
    t = np.arange(0.0, 7200.0, 1.0)
    frame = _frame(t, FI=5.0 + 0.5 * np.sin(t / 600.0), TI=80.0 + 0.0 * t)
    s = HistorianSettings(tags={"FI": TagSettings(scan=1.0, deadband=0.02, heartbeat=600.0),
                                "TI": TagSettings(scan=30.0, deadband=0.2, heartbeat=900.0)},
                          start="2026-03-01T12:00:00+01:00", outages_per_day=0.0, seed=2)
    h = export_history(frame, s)
    long_path = h.write(tmp_path / "long.csv")
    text = long_path.read_text().splitlines()
    assert text[0] == "tag,time,value"
    # ISO 8601 in UTC with the offset written out: 12:00 at +01:00 is 11:00 UTC
    first_ti = next(line for line in text if line.startswith("TI,"))
    stamp = first_ti.split(",")[1]
    assert stamp.endswith("+00:00") and stamp.startswith("2026-03-01T11:")
    assert pd.Timestamp(stamp) == pd.Timestamp("2026-03-01T11:00:00Z") + pd.Timedelta(
        seconds=float(h.records[h.records["tag"] == "TI"]["time"].iloc[0]))
    df = read_table(long_path, required=["FI", "TI"])
    offset = float(h.records["time"].min())  # read_table counts from the earliest record
    for tag in ("FI", "TI"):
        rec = h.records[h.records["tag"] == tag]
        got = df[["time", tag]].dropna()
        np.testing.assert_allclose(got["time"] + offset, rec["time"], atol=1e-9)
        np.testing.assert_allclose(got[tag], rec["value"], rtol=1e-8)
    wide = read_table(h.write(tmp_path / "wide.csv", "wide"), allow_nan=True)
    assert list(wide.columns) == ["time", "FI", "TI"]
    np.testing.assert_allclose(wide[["time", "FI", "TI"]].to_numpy(), df[["time", "FI", "TI"]].to_numpy(),
                               equal_nan=True, rtol=1e-8)
    # the steady TI is archived only by heartbeat: about 7200 / 900 records
    assert 7 <= int(np.isfinite(df["TI"]).sum()) <= 10


def test_view_of_an_export_follows_the_frame_within_the_dead_band(tmp_path):
    # the data layer's reconstruction of an export (hold, heartbeat rule) stays within the dead band plus
    # one scan's move of the frame, and a communication loss is NaN from its bad event to the next record
    t = np.arange(0.0, DAY / 2, 1.0)
    ti = 80.0 + 2.0 * np.sin(2 * np.pi * t / 7200.0)
    fi = 5.0 + 0.0 * t
    s = HistorianSettings(tags={"TI": TagSettings(scan=5.0, deadband=0.1, heartbeat=600.0),
                                "FI": TagSettings(scan=10.0, deadband=0.05, heartbeat=600.0)},
                          outages_per_day=6.0, outage_duration=(1200.0, 2400.0), outage_all_tags=1.0, seed=4)
    h = export_history(_frame(t, FI=fi, TI=ti), s)
    path = h.write(tmp_path / "m.csv")
    spec = Spec(path=tmp_path / "s.toml", twin=tmp_path / "t.fmu", measurements=path, sample_time=10.0,
                inputs={"FI": "u"}, outputs={"TI": "y"}, data=DataRules(heartbeat=h.heartbeats()))
    v = MeasurementView.from_spec(spec)
    offset = float(h.records["time"].min())
    truth = np.interp(v.grid + offset, t, ti)
    got = v.values("TI")
    ok = np.isfinite(got)
    # max move of the sine over one scan with jitter: 2 * 2 pi / 7200 * 7 s ~ 0.012
    assert np.abs(got[ok] - truth[ok]).max() <= 0.1 + 0.02
    # every communication loss is NaN on the grid (from the first scan after its start to its end)
    assert h.outages
    for o in h.outages:
        inside = (v.grid + offset > o.start + 5.0 * 1.4) & (v.grid + offset < o.stop)
        assert np.isnan(got[inside]).all()
    # and outside the losses nothing is missing (the steady stretches are not gaps)
    lost = np.zeros(v.grid.size, dtype=bool)
    for o in h.outages:
        lost |= (v.grid + offset >= o.start) & (v.grid + offset < o.stop + 5.0 * 1.4 + 10.0)
    assert ok[~lost & (v.grid + offset > 10.0)].all()


@pytest.mark.parametrize(("tag", "problem"), [
    (TagSettings(scan=0.5), "scan = 0.5 s is outside 1..60 s"),
    (TagSettings(scan=61.0, heartbeat=900.0), "scan = 61.0 s is outside 1..60 s"),
    (TagSettings(jitter=0.5), "jitter = 0.5 must be in [0, 0.5)"),
    (TagSettings(deadband=-1.0), "deadband = -1.0 must be a finite number >= 0"),
    (TagSettings(scan=30.0, heartbeat=10.0), "heartbeat = 10.0 s must be finite and at least the scan"),
])
def test_bad_settings_name_the_tag(tag, problem):
    frame = _frame(np.arange(0.0, 100.0), TI=np.ones(100))
    with pytest.raises(SpecError, match="tag 'TI'") as err:
        export_history(frame, HistorianSettings(tags={"TI": tag}))
    assert problem in str(err.value)


def test_bad_frames_and_names():
    t = np.arange(0.0, 100.0)
    with pytest.raises(DataError, match="no 'time' column"):
        export_history(pd.DataFrame({"Time": t, "TI": t}))
    with pytest.raises(DataError, match="strictly increasing"):
        export_history(_frame(t[::-1], TI=t))
    with pytest.raises(DataError, match="tag 'TJ' is not a column of the frame"):
        export_history(_frame(t, TI=t), tags=["TJ"])
    with pytest.raises(DataError, match="tag 'TI' has non-finite values, first at t = 3 s"):
        export_history(_frame(t, TI=np.where(t == 3, np.nan, t)))
    with pytest.raises(SpecError, match="settings name tag 'FX'"):
        export_history(_frame(t, TI=t), HistorianSettings(tags={"FX": TagSettings()}))
    with pytest.raises(SpecError, match="no UTC offset"):
        export_history(_frame(t, TI=t), HistorianSettings(start="2026-03-01T12:00:00"))
