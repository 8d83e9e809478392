"""Data layer: CSV reading/validation, resampling without bridging gaps, windows, NaN spans."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from trackingbox.data import nan_spans, read_table, resample, window
from trackingbox.errors import DataError


def write(tmp_path, text, name="measurements.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_numeric_time(tmp_path):
    df = read_table(write(tmp_path, "time,TI-301,FI-101\n0,20.5,1\n10,21.0,1.5\n20,21.5,2\n"),
                    required=["TI-301"])
    assert list(df.columns) == ["time", "TI-301", "FI-101"]
    assert df["time"].tolist() == [0.0, 10.0, 20.0]
    assert df["TI-301"].tolist() == [20.5, 21.0, 21.5]
    assert df.attrs["t0"] is None


def test_iso_time_becomes_seconds_from_first_row(tmp_path):
    df = read_table(write(tmp_path, "time,T\n2026-03-01T10:00:00,1\n2026-03-01T10:00:10,2\n"
                                    "2026-03-01T11:00:00,3\n"))
    assert df["time"].tolist() == [0.0, 10.0, 3600.0]
    assert df.attrs["t0"] == pd.Timestamp("2026-03-01T10:00:00")


def test_iso_time_with_offset(tmp_path):
    df = read_table(write(tmp_path, "time,T\n2026-03-01T10:00:00+01:00,1\n2026-03-01T09:01:00Z,2\n"))
    assert df["time"].tolist() == [0.0, 60.0]


def test_missing_required_columns_suggest(tmp_path):
    with pytest.raises(DataError) as exc:
        read_table(write(tmp_path, "time,TI-301\n0,1\n"), required=["TI-310", "FI-101"])
    msg = str(exc.value)
    assert "tag 'TI-310' is missing from measurements.csv (did you mean 'TI-301'?)" in msg
    assert "tag 'FI-101' is missing" in msg


def test_no_time_column(tmp_path):
    with pytest.raises(DataError, match=r"no 'time' column \(did you mean 'Time'\?\)"):
        read_table(write(tmp_path, "Time,T\n0,1\n"))


def test_non_numeric_cell_names_line_and_column(tmp_path):
    with pytest.raises(DataError, match=r"tag 'T' in measurements.csv has non-numeric values: 'abc' on line 3"):
        read_table(write(tmp_path, "time,T\n0,1\n10,abc\n20,3\n"))


def test_non_monotonic_time_names_first_row_and_time(tmp_path):
    with pytest.raises(DataError, match=r"goes backwards: line 4 has 15 s after 20 s on line 3"):
        read_table(write(tmp_path, "time,T\n0,1\n20,2\n15,3\n30,4\n"))


def test_duplicate_time(tmp_path):
    with pytest.raises(DataError, match=r"duplicate times: line 4 repeats 10 s"):
        read_table(write(tmp_path, "time,T\n0,1\n10,2\n10,3\n"))


def test_nan_values_count_and_span(tmp_path):
    # 412 empty cells of TI-301 from t = 600 s to t = 1011 s (1 s sampling, one row per second)
    t = np.arange(0, 1200)
    vals = np.where((t >= 600) & (t < 1012), np.nan, 20.0)
    df = pd.DataFrame({"time": t, "TI-301": vals})
    path = tmp_path / "measurements.csv"
    df.to_csv(path, index=False)
    with pytest.raises(DataError) as exc:
        read_table(path)
    assert str(exc.value) == "tag 'TI-301' in measurements.csv has 412 NaN values between 600 s and 1011 s"
    ok = read_table(path, allow_nan=True)
    assert int(ok["TI-301"].isna().sum()) == 412


def test_all_problems_reported_together(tmp_path):
    path = write(tmp_path, "time,A,B\n0,1,x\n10,,2\n5,3,4\n", name="inputs.csv")
    with pytest.raises(DataError) as exc:
        read_table(path, required=["C"], what="inputs")
    msg = str(exc.value)
    assert msg.startswith("inputs file inputs.csv has 4 problems:")
    for part in ("column 'C' is missing", "goes backwards: line 4 has 5 s",
                 "column 'B' in inputs.csv has non-numeric values: 'x' on line 2",
                 "column 'A' in inputs.csv has 1 NaN value at 10 s"):
        assert part in msg


@pytest.mark.parametrize("content, problem", [
    (None, "does not exist"),
    (b"PK\x03\x04\x14\x00\x00\x00\x08\x00\xff\xfe\xfd", "not a CSV text file"),
    (b"", "cannot be read as CSV"),
    (b"time,T\n", "no data rows"),
])
def test_unreadable_files(tmp_path, content, problem):
    path = tmp_path / "data.csv"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(DataError) as exc:
        read_table(path)
    assert problem in str(exc.value) and "data.csv" in str(exc.value)


def test_resample_interpolates_per_column_and_never_across_long_gaps():
    df = pd.DataFrame({
        "time": [0.0, 10.0, 20.0, 30.0, 100.0, 110.0],
        "A": [0.0, 1.0, 2.0, 3.0, 10.0, 11.0],        # 70 s gap between 30 and 100
        "B": [0.0, np.nan, 4.0, 6.0, np.nan, np.nan],  # short NaN gap, valid only up to t = 30
    })
    out = resample(df, [5.0, 15.0, 30.0, 50.0, 100.0, 105.0, 120.0], max_gap=40.0)
    assert out["time"].tolist() == [5.0, 15.0, 30.0, 50.0, 100.0, 105.0, 120.0]
    a, b = out["A"].to_numpy(), out["B"].to_numpy()
    # A: linear inside short spans, NaN inside the 70 s gap (but kept at the sample at 100 s),
    # NaN after the last sample
    assert np.allclose(a[[0, 1, 2, 4, 5]], [0.5, 1.5, 3.0, 10.0, 10.5])
    assert np.isnan(a[3]) and np.isnan(a[6])
    # B: bridges its own 20 s NaN gap (0 -> 4 between 0 and 20 s), NaN beyond its last valid sample
    assert np.allclose(b[[0, 1, 2]], [1.0, 3.0, 6.0])
    assert np.all(np.isnan(b[3:]))
    # without max_gap the long gap of A is bridged linearly: 3 + 7 * 20/70 at 50 s
    assert resample(df, [50.0])["A"].iloc[0] == pytest.approx(3.0 + 7.0 * 20.0 / 70.0)


def test_window_is_half_open():
    df = pd.DataFrame({"time": [0.0, 10.0, 20.0, 30.0], "T": [1.0, 2.0, 3.0, 4.0]})
    w = window(df, 10.0, 30.0)
    assert w["time"].tolist() == [10.0, 20.0] and w.index.tolist() == [0, 1]
    with pytest.raises(DataError, match="ends before it starts"):
        window(df, 30.0, 10.0)


def test_nan_spans():
    s = pd.Series([np.nan, 1.0, np.nan, np.nan, 2.0, np.nan])
    t = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0]
    assert nan_spans(s, t) == [(0.0, 0.0), (20.0, 30.0), (50.0, 50.0)]
    assert nan_spans(pd.Series([1.0, 2.0])) == []


# --------------------------------------------------------------------------- the measurement view

from trackingbox.data import MeasurementView, default_max_gap, fill_nan  # noqa: E402
from trackingbox.errors import SpecError  # noqa: E402
from trackingbox.spec import DataRules, Spec, StoppageRule  # noqa: E402


def _spec(tmp_path, csv_text, *, max_gap=None, stoppage=None, windows=None, sample_time=10.0):
    path = write(tmp_path, csv_text)
    return Spec(path=tmp_path / "spec.toml", twin=tmp_path / "twin.fmu", measurements=path,
                sample_time=sample_time, inputs={"FI": "u"}, outputs={"TI": "y"},
                windows=windows or {}, data=DataRules(stoppage=stoppage, max_gap=max_gap))


def _rows(times, **columns):
    """CSV text; a column's value None is an empty cell."""
    names = list(columns)
    lines = ["time," + ",".join(names)]
    for i, t in enumerate(times):
        cells = ["" if columns[n][i] is None else repr(float(columns[n][i])) for n in names]
        lines.append(f"{t:g}," + ",".join(cells))
    return "\n".join(lines) + "\n"


def test_fill_nan_interpolates_and_holds_the_ends():
    assert fill_nan([np.nan, 2.0, np.nan, np.nan, 8.0, np.nan]).tolist() == [2.0, 2.0, 4.0, 6.0, 8.0, 8.0]
    assert np.isnan(fill_nan([np.nan, np.nan])).all()


def test_default_gap_is_two_and_a_half_median_intervals_of_the_tag():
    # spacing 10, 10, 10, 40: median 10 -> 25 s
    assert default_max_gap([0, 10, 20, 30, 70], [1, 1, 1, 1, 1]) == 25.0
    # NaN samples do not count: valid at 0, 30, 60 -> median 30 -> 75 s
    assert default_max_gap([0, 10, 20, 30, 60], [1, np.nan, np.nan, 1, 1]) == 75.0
    assert default_max_gap([0, 10], [1, np.nan]) == np.inf


def test_view_irregular_tags_are_bridged_and_a_hole_is_masked(tmp_path):
    # FI every 10 s; TI every 30 s (empty cells between) with its samples from 90 to 150 s missing:
    # valid TI at 0, 30, 60, 180, 210; median 30 -> gap limit 75 s; 60 -> 180 is 120 s: grid points
    # 70 .. 170 are masked, 10, 20, 40, 50 interpolated by hand, 180 and 200 exact / interpolated
    t = np.arange(0.0, 220.0, 10.0)
    ti = [float(x) if x % 30 == 0 and not 90 <= x <= 150 else None for x in t]
    spec = _spec(tmp_path, _rows(t, FI=np.full(t.size, 5.0), TI=ti))
    v = MeasurementView.from_spec(spec)
    assert v.max_gap == {"FI": 25.0, "TI": 75.0}
    assert v.grid.tolist() == t.tolist()
    expected = [x if not 70 <= x <= 170 else np.nan for x in t]  # TI = time where valid (linear)
    np.testing.assert_array_equal(v.values("TI"), expected)
    assert v.gaps("TI") == [(70.0, 170.0)]
    assert v.scored["TI"].tolist() == [not 70 <= x <= 170 for x in t]
    assert (v.inputs["u"] == 5.0).all() and v.inputs["time"].tolist() == t.tolist()


def test_view_max_gap_of_the_spec_rules_every_tag(tmp_path):
    t = np.arange(0.0, 220.0, 10.0)
    ti = [float(x) if x % 30 == 0 and not 90 <= x <= 150 else None for x in t]
    spec = _spec(tmp_path, _rows(t, FI=np.full(t.size, 5.0), TI=ti), max_gap=200.0)
    v = MeasurementView.from_spec(spec)
    assert v.max_gap == {"FI": 200.0, "TI": 200.0}
    np.testing.assert_allclose(v.values("TI"), t[:-1].tolist() + [t[-1]])  # the hole is bridged: TI = time
    spec = _spec(tmp_path, _rows(t, FI=np.full(t.size, 5.0), TI=ti), max_gap=20.0)
    v = MeasurementView.from_spec(spec)
    # 30 s between TI samples is already a gap: only the samples themselves remain
    assert np.flatnonzero(np.isfinite(v.values("TI"))).tolist() == [0, 3, 6, 18, 21]


def test_view_stoppage_with_settle_window_lead_and_skip(tmp_path):
    # FI below 1 from 100 to 130 s (samples every 10 s): stopped 100..130, settle 25 s -> up to 155
    # (grid points 140 and 150); window [60, 200), lead 30 s -> grid from 30; skip 70 s
    t = np.arange(0.0, 250.0, 10.0)
    fi = np.where((t >= 100) & (t <= 130), 0.0, 5.0)
    ti = 20.0 + t / 10.0
    ti[t == 180.0] = np.nan
    spec = _spec(tmp_path, _rows(t, FI=fi, TI=ti), stoppage=StoppageRule("FI", 1.0, 25.0),
                 windows={"training": (60.0, 200.0)})
    v = MeasurementView.from_spec(spec, "training", lead=30.0, skip=70.0)
    assert v.grid.tolist() == list(np.arange(30.0, 200.0, 10.0))
    assert v.lead == 3 and v.window == (60.0, 200.0)
    assert v.grid[v.stopped].tolist() == [100.0, 110.0, 120.0, 130.0, 140.0, 150.0]
    # one NaN sample (a 20 s hole, below 2.5 x 10 s) is bridged: 180 s is interpolated, scored
    assert v.values("TI")[v.grid == 180.0].tolist() == [38.0]
    scored = v.grid[v.scored["TI"]].tolist()
    assert scored == [70.0, 80.0, 90.0, 160.0, 170.0, 180.0, 190.0]
    assert v.scored_counts() == {"TI": 7}
    assert np.isnan(v.scored_values("TI")[v.grid == 60.0]).all()


def test_view_stops_at_the_last_row_and_names_bad_input(tmp_path):
    t = np.arange(0.0, 55.0, 10.0)
    spec = _spec(tmp_path, _rows(t, FI=np.ones(t.size), TI=np.ones(t.size)),
                 windows={"validation": (30.0, 100.0), "training": (45.0, 49.0)})
    v = MeasurementView.from_spec(spec, "validation")
    assert v.grid.tolist() == [0.0, 10.0, 20.0, 30.0, 40.0, 50.0]  # not past the last row
    with pytest.raises(SpecError, match="no \\[windows\\] calibration.*validation, training"):
        MeasurementView.from_spec(spec, "calibration")  # type: ignore[arg-type]
    with pytest.raises(DataError, match="holds 0 grid point"):
        MeasurementView.from_spec(spec, "training")
    bad = _spec(tmp_path, _rows(t, FI=np.ones(t.size), TJ=np.ones(t.size)))
    with pytest.raises(DataError, match="tag 'TI' is missing from measurements.csv"):
        MeasurementView.from_spec(bad)
    with pytest.raises(DataError, match="'TX' is not in the measurement view"):
        v.values("TX")


def test_view_as_a_table_and_an_open_ended_window(tmp_path):
    t = np.arange(0.0, 60.0, 10.0)
    fi = np.array([5.0, 5.0, 0.0, 5.0, 5.0, 5.0])
    spec = _spec(tmp_path, _rows(t, FI=fi, TI=t + 1.0), stoppage=StoppageRule("FI", 1.0, 0.0))
    v = MeasurementView.from_spec(spec, (10.0, float("inf")))
    assert v.grid.tolist() == t.tolist()
    frame = v.to_frame()
    assert list(frame.columns) == ["time", "FI", "TI"] and frame["TI"].tolist() == (t + 1.0).tolist()
    # scored: from 10 s on, not at the stopped 20 s
    assert v.to_frame(scored=True)["TI"].isna().tolist() == [True, False, True, False, False, False]
    assert v.to_frame(scored=True)["FI"].tolist() == fi.tolist()  # not an output: unchanged


# --------------------------------------------------------------------------- historian exports
# A plant historian's long export (tag,time,value; ISO 8601 UTC; an empty value is a bad-quality
# event) read by hand-checkable examples: the expected values below are worked out from the rows.

START = pd.Timestamp("2026-03-01T10:00:00+00:00")


def _long(records):
    """CSV text of ``(tag, seconds from START, value or None)`` rows, in the order given."""
    lines = ["tag,time,value"]
    for tag, s, v in records:
        stamp = (START + pd.Timedelta(seconds=s)).isoformat(timespec="milliseconds")
        lines.append(f"{tag},{stamp},{'' if v is None else repr(float(v))}")
    return "\n".join(lines) + "\n"


# TI: exception-reported (heartbeat 600 s) with jittered timestamps: steady at 80 (archived by
# heartbeat only), a step to 81 at 1250.4 s, a communication loss from 1900.2 s (bad event) to
# 3100.7 s, then 82. LI: steady, heartbeat records, silent from 1200 to 2500 s with no bad event
# (longer than 1.5 x 600 s: missing). FI: the twin's input, every 600 s.
HISTORY = (
    [("FI", s, 5.0) for s in (0.0, 600.0, 1200.0, 1800.0, 2400.0, 3000.0, 3600.0, 3700.0)]
    + [("LI", 0.0, 1.0), ("LI", 600.0, 1.0), ("LI", 1200.0, 1.0), ("LI", 2500.0, 1.5),
       ("LI", 3100.0, 1.5), ("LI", 3700.0, 1.5)]
    + [("TI", 0.0, 80.0), ("TI", 597.3, 80.0), ("TI", 1190.8, 80.0), ("TI", 1250.4, 81.0),
       ("TI", 1850.9, 81.0), ("TI", 1900.2, None), ("TI", 3100.7, 82.0), ("TI", 3700.0, 82.0)]
)


def test_long_export_is_read_wide_with_its_bad_events(tmp_path):
    text = "tag,time,value\nTI,2026-03-01T10:00:00.000+00:00,80\nTI,2026-03-01T10:00:09.250+00:00,\n" \
           "TI,2026-03-01T10:01:00.000+00:00,81.5\nFI,2026-03-01T09:59:59.500+00:00,5\n" \
           "FI,2026-03-01T10:00:30.000+00:00,4\n"
    df = read_table(write(tmp_path, text), required=["TI", "FI"], allow_nan=True)
    # seconds from the earliest timestamp (FI's, on line 5), one row per time
    assert df["time"].tolist() == [0.0, 0.5, 9.75, 30.5, 60.5]
    assert list(df.columns) == ["time", "TI", "FI"]
    np.testing.assert_array_equal(df["TI"], [np.nan, 80.0, np.nan, np.nan, 81.5])
    np.testing.assert_array_equal(df["FI"], [5.0, np.nan, np.nan, 4.0, np.nan])
    assert df.attrs["breaks"] == {"TI": (9.75,)}
    assert df.attrs["t0"] == pd.Timestamp("2026-03-01T09:59:59.500+00:00")


def test_long_export_problems_name_tag_and_line(tmp_path):
    text = "tag,time,value\nTI,2026-03-01T10:00:00+00:00,80\nTI,2026-03-01T10:00:00+00:00,81\n" \
           "FI,2026-03-01T10:00:10+00:00,x\nFI,2026-03-01T10:00:05+00:00,4\nPI,2026-03-01T10:00:05+00:00,\n"
    with pytest.raises(DataError) as err:
        read_table(write(tmp_path, text), required=["PIX"])
    msg = str(err.value)
    assert "5 problems" in msg, msg
    assert "tag 'TI' in measurements.csv has duplicate times: line 3 repeats 0 s" in msg
    assert "column 'value' in measurements.csv has non-numeric values: 'x' on line 4" in msg
    assert "tag 'FI' in measurements.csv goes backwards: line 5 has 5 s after 10 s on line 4" in msg
    assert "tag 'PI' in measurements.csv has 1 bad-quality value (empty 'value'), first on line 6" in msg
    assert "tag 'PIX' is missing from measurements.csv (did you mean 'PI'?)" in msg


def test_resample_hold_keeps_the_last_value_and_stops_at_a_bad_event():
    df = pd.DataFrame({"time": [0.0, 100.0, 130.0, 400.0], "y": [1.0, 2.0, 3.0, 4.0]})
    g = [0.0, 50.0, 100.0, 120.0, 200.0, 400.0, 450.0, 600.0]
    # gap limit 250: 130 -> 400 (270 s) is a gap; after the last sample hold for 250 s (to 650)
    out = resample(df, g, max_gap=250.0, method="hold")["y"].tolist()
    np.testing.assert_array_equal(out, [1.0, 1.0, 2.0, 2.0, np.nan, 4.0, 4.0, 4.0])
    # a bad event at 150 s: the loss begins there (the silence before it is 20 s, not a gap)
    out = resample(df, g + [140.0], max_gap=250.0, method="hold", breaks={"y": [150.0]})["y"].tolist()
    np.testing.assert_array_equal(out, [1.0, 1.0, 2.0, 2.0, np.nan, 4.0, 4.0, 4.0, 3.0])
    # linear interpolation never crosses the bad event either
    out = resample(df, [50.0, 140.0, 200.0], breaks={"y": [150.0]})["y"].tolist()
    np.testing.assert_array_equal(out, [1.5, np.nan, np.nan])


def _history_spec(tmp_path, records, heartbeat, **rules):
    path = write(tmp_path, _long(records))
    return Spec(path=tmp_path / "spec.toml", twin=tmp_path / "twin.fmu", measurements=path, sample_time=10.0,
                inputs={"FI": "u"}, outputs={"TI": "y"}, data=DataRules(heartbeat=heartbeat, **rules))


def test_view_of_an_exception_reported_history(tmp_path):
    spec = _history_spec(tmp_path, HISTORY, {"*": 600.0})
    v = MeasurementView.from_spec(spec, tags=["LI"])
    g = v.grid
    assert g[0] == 0.0 and g[-1] == 3700.0
    assert v.max_gap == {"FI": 900.0, "TI": 900.0, "LI": 900.0}
    assert v.method == {"FI": "hold", "TI": "hold", "LI": "hold"}
    # TI: steady 80 archived by heartbeat only is NOT a gap; the step is held from its record;
    # the communication loss stays NaN from the bad event to the next record
    expected_ti = np.select([g < 1250.4, g < 1900.2, g < 3100.7], [80.0, 81.0, np.nan], 82.0)
    np.testing.assert_array_equal(v.values("TI"), expected_ti)
    assert v.gaps("TI") == [(1910.0, 3100.0)]
    # LI: 1300 s of silence without a bad event is longer than 1.5 x 600 s: missing in between
    expected_li = np.select([g <= 1200.0, g < 2500.0], [1.0, np.nan], 1.5)
    np.testing.assert_array_equal(v.values("LI"), expected_li)
    # the input is held at its records and never NaN
    assert (v.inputs["u"] == 5.0).all()
    # scored: every valid TI point
    assert v.scored["TI"].tolist() == np.isfinite(expected_ti).tolist()


def test_steady_dead_banded_tag_is_not_a_gap_but_the_median_rule_made_it_one(tmp_path):
    # TI moves for 5 minutes (a record every 10 s), then is steady: heartbeat records every 600 s
    busy = [("TI", float(s), 80.0 + s / 100.0) for s in range(0, 300, 10)]
    steady = [("TI", s, 82.9) for s in (890.0, 1490.0, 2090.0)]
    fi = [("FI", float(s), 5.0) for s in range(0, 2100, 600)] + [("FI", 2090.0, 5.0)]
    records = fi + busy + steady
    old = MeasurementView.from_spec(_history_spec(tmp_path, records, {}))
    # the median rule: median spacing 10 s -> gaps longer than 25 s; the steady stretch is "missing"
    quiet = (old.grid > 290) & (old.grid < 2090) & ~np.isin(old.grid, [890.0, 1490.0])  # the records stay
    assert old.max_gap["TI"] == 25.0 and np.isnan(old.values("TI")[quiet]).all()
    new = MeasurementView.from_spec(_history_spec(tmp_path, records, {"TI": 600.0, "FI": 600.0}))
    ti = new.values("TI")
    g = new.grid
    # held: each busy record until the next (80 + s/100 at s = 0, 10, .., 290 s), then 82.9, the last
    # busy value, confirmed by the heartbeat records at 890, 1490 and 2090 s: never missing
    np.testing.assert_allclose(ti[g < 300], 80.0 + np.floor(g[g < 300] / 10.0) / 10.0)
    np.testing.assert_allclose(ti[g >= 300], 82.9)
    assert not np.isnan(ti).any()


def test_jittered_records_of_one_tag_are_used_at_their_own_times(tmp_path):
    # FI and TI archived at scan times moved by jitter; hold reconstruction at each grid point takes
    # the record at or before it
    ti = [("TI", 0.0, 1.0), ("TI", 9.7, 2.0), ("TI", 20.3, 3.0), ("TI", 29.9, 4.0), ("TI", 40.2, 5.0)]
    fi = [("FI", 0.4, 5.0), ("FI", 40.0, 5.0)]
    v = MeasurementView.from_spec(_history_spec(tmp_path, ti + fi, {"*": 60.0}))
    assert v.grid.tolist() == [0.0, 10.0, 20.0, 30.0, 40.0]
    assert v.values("TI").tolist() == [1.0, 2.0, 2.0, 4.0, 4.0]
    # FI's first record is at 0.4 s: nothing is known before it
    assert np.isnan(v.values("FI")[0]) and v.values("FI")[1:].tolist() == [5.0] * 4


def test_stoppage_of_a_flow_falling_to_zero_in_a_minute_is_masked(tmp_path):
    """The feed flow ramps from 5 to 0 kg/s over 60 s at 1000 s, stays at ~0 for 30 min, ramps back.

    Archived by exception (dead band 0.05 kg/s, scan 2 s, heartbeat 600 s). Rule: stopped below
    0.5 kg/s, 300 s settle. By hand: the ramp crosses 0.5 kg/s at 1054 s (down) and at 2866 s
    (up); with held values the grid (10 s) is below 0.5 kg/s from 1060 s (the record at 1060 s is 0;
    1050 s holds 0.83) to 2860 s (2870 s holds 0.83): the mask runs from 1060 s to 2860 + 300 s.
    """
    t = np.arange(0.0, 4000.0, 2.0)
    flow = np.interp(t, [0.0, 1000.0, 1060.0, 2860.0, 2920.0, 4000.0], [5.0, 5.0, 0.0, 0.0, 5.0, 5.0])
    records, last_t, last_v = [], -1e9, None
    for s, f in zip(t, flow):  # exception reporting written out by hand
        if last_v is None or abs(f - last_v) > 0.05 or s - last_t >= 600.0:
            records.append(("FI", float(s), float(f)))
            last_t, last_v = s, f
    records += [("TI", float(s), 80.0) for s in range(0, 4000, 600)] + [("TI", 3998.0, 80.0)]
    spec = _history_spec(tmp_path, records, {"*": 600.0}, stoppage=StoppageRule("FI", 0.5, 300.0))
    v = MeasurementView.from_spec(spec)
    stopped = v.grid[v.stopped]
    assert stopped[0] == 1060.0 and stopped[-1] == 3160.0
    assert np.all(np.diff(stopped) == 10.0)  # one stretch
    assert not v.scored["TI"][v.stopped].any()


# --------------------------------------------------------------------------- [data] heartbeat in the spec

from trackingbox.spec import loads_spec, write_spec  # noqa: E402

SPEC_TOML = """
twin = "twin.fmu"
measurements = "m.csv"
sample_time = 10.0
[inputs]
FI = "u"
[outputs]
TI = "y"
[data]
{data}
"""


def test_spec_heartbeat_for_every_tag_or_per_tag(tmp_path):
    spec = loads_spec(SPEC_TOML.format(data="heartbeat = 600"), tmp_path / "s.toml", check_files=False)
    assert spec.data.heartbeat_of("TI") == 600.0 and spec.data.heartbeat_of("FI") == 600.0
    spec = loads_spec(SPEC_TOML.format(data="[data.heartbeat]\nTI = 900\n\"*\" = 300"), tmp_path / "s.toml",
                      check_files=False)
    assert spec.data.heartbeat_of("TI") == 900.0 and spec.data.heartbeat_of("FI") == 300.0
    spec = loads_spec(SPEC_TOML.format(data="[data.heartbeat]\nTI = 900"), tmp_path / "s.toml", check_files=False)
    assert spec.data.heartbeat_of("FI") is None
    # written back and read again: the same rules
    again = loads_spec(write_spec(spec, tmp_path / "back.toml").read_text(), tmp_path / "back.toml",
                       check_files=False)
    assert dict(again.data.heartbeat) == {"TI": 900.0}


def test_spec_heartbeat_problems_are_named(tmp_path):
    with pytest.raises(SpecError) as err:
        loads_spec(SPEC_TOML.format(data="[data.heartbeat]\nTIX = 900\nFI = -1"), tmp_path / "s.toml",
                   check_files=False)
    msg = str(err.value)
    assert "unknown tag 'TIX' in [data.heartbeat] (did you mean 'TI'?)" in msg
    assert "'FI' in [data.heartbeat] must be > 0" in msg
    with pytest.raises(SpecError, match="'heartbeat' in \\[data\\] must be a number"):
        loads_spec(SPEC_TOML.format(data='heartbeat = "10 min"'), tmp_path / "s.toml", check_files=False)


def test_spec_checks_the_tags_of_a_long_export(tmp_path):
    (tmp_path / "twin.fmu").write_bytes(b"")
    (tmp_path / "m.csv").write_text(_long([("FI", 0.0, 5.0), ("TI", 0.0, 80.0), ("TI", 10.0, 81.0)]))
    spec = loads_spec(SPEC_TOML.format(data="heartbeat = 600"), tmp_path / "s.toml")
    assert spec.data.heartbeat_of("TI") == 600.0
    (tmp_path / "m.csv").write_text(_long([("FI", 0.0, 5.0), ("TJ", 0.0, 80.0)]))
    with pytest.raises(SpecError, match="tag 'TI' is not a column of m.csv"):
        loads_spec(SPEC_TOML.format(data="heartbeat = 600"), tmp_path / "s.toml")


# --------------------------------------------------------------------------- lost tags: held inputs, lost stoppage tag


def test_input_gap_is_held_and_masked_with_the_settle_time(tmp_path):
    # FI is the twin's input and TI the output (10 s rows); FI is lost from 100 to 150 s (empty cells,
    # beyond max_gap 15 s); the stoppage rule (on TI, never below 0) has a 25 s settle time
    t = np.arange(0.0, 250.0, 10.0)
    fi = [None if 100.0 <= s <= 150.0 else 1.0 + s / 100.0 for s in t]
    spec = _spec(tmp_path, _rows(t, FI=fi, TI=np.full(t.size, 50.0)), max_gap=15.0,
                 stoppage=StoppageRule("TI", -1.0, 25.0))
    v = MeasurementView.from_spec(spec)
    gap = (v.grid >= 100.0) & (v.grid <= 150.0)
    # held at the last good value (90 s: 1.9), not interpolated towards the next (160 s: 2.6)
    assert (v.inputs["u"][gap] == 1.9).all()
    assert v.grid[v.input_gap].tolist() == [100.0, 110.0, 120.0, 130.0, 140.0, 150.0]
    # masked like a stoppage: the gap and 25 s after it (160 and 170 s)
    assert v.grid[v.stopped].tolist() == [100.0, 110.0, 120.0, 130.0, 140.0, 150.0, 160.0, 170.0]
    assert v.grid[~v.scored["TI"]].tolist() == v.grid[v.stopped].tolist()
    assert not v.stoppage_unknown.any()


def test_stoppage_tag_lost_during_a_stoppage_is_masked_through_the_loss(tmp_path):
    """The feed stops at 1000 s; its flow tag is lost (bad-quality event) from 1500 s until 2500 s,
    while the feed is still stopped; the feed restarts at 2800 s. Rule: stopped below 0.5, 300 s settle.

    By hand: stopped 1000..1490 s (held 0 records), unknown 1500..2490 s, stopped again 2500..2790 s,
    then the settle to 2790 + 300 = 3090 s: one stretch 1000..3090 s. Without the loss rule the
    mask had a hole at 1500..2490 s (only 1500 + 300 = 1790 s were covered by the settle).
    """
    records = [("FI", float(s), 5.0) for s in range(0, 1000, 100)]
    records += [("FI", 1000.0, 0.0), ("FI", 1200.0, 0.0), ("FI", 1400.0, 0.0), ("FI", 1500.0, None),
                ("FI", 2500.0, 0.0), ("FI", 2700.0, 0.0)]
    records += [("FI", float(s), 5.0) for s in range(2800, 4000, 100)]
    records += [("TI", float(s), 80.0) for s in range(0, 4000, 300)]
    records.sort(key=lambda r: r[1])
    spec = _history_spec(tmp_path, records, {"*": 600.0}, stoppage=StoppageRule("FI", 0.5, 300.0))
    v = MeasurementView.from_spec(spec)
    g = v.grid
    assert g[v.stoppage_unknown].tolist() == list(np.arange(1500.0, 2500.0, 10.0))
    assert g[v.stopped].tolist() == list(np.arange(1000.0, 3100.0, 10.0))
    assert not v.scored["TI"][(g >= 1000.0) & (g <= 3090.0)].any()
    assert v.scored["TI"][g == 3100.0].all()


def test_stoppage_tag_lost_while_running_is_masked_conservatively(tmp_path):
    # the tag is lost for 200 s while the feed runs: the plant may have stopped unseen, so the loss and
    # the settle time after it are masked (the outputs there are not scored)
    t = np.arange(0.0, 1000.0, 10.0)
    fi = [None if 400.0 <= s < 600.0 else 5.0 for s in t]
    spec = _spec(tmp_path, _rows(t, FI=fi, TI=np.full(t.size, 50.0)), max_gap=15.0,
                 stoppage=StoppageRule("FI", 0.5, 100.0))
    v = MeasurementView.from_spec(spec)
    assert v.grid[v.stopped].tolist() == list(np.arange(400.0, 700.0, 10.0))
