"""A long run's measurements window by window (trackingbox.stream) against the whole measurement view.

The expectation is the whole view (``MeasurementView.from_spec``) of the same file: every stretch of
rows a window gives must be that view's rows, bit for bit, wherever the stretch starts, in whatever
order the stretches are asked for; the whole-run statistics must be the ones computed on its arrays.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import trackingbox.data.table as data_table
import trackingbox.stream as stream
from trackingbox.data import MeasurementView
from trackingbox.spec import DataRules, Spec, StoppageRule
from trackingbox.stream import WindowedMeasurements

ROWS = 700  # 10 s rows: several reader chunks and index entries at the sizes patched below


def _case(tmp_path: Path, *, max_gap: float | None = None, heartbeat: bool = False) -> Spec:
    """A wide CSV with what the windows must reproduce exactly, and its spec.

    ``FI`` (input, stoppage tag): missing at first, a stoppage at rows 300-319 (settle 55 s) and a
    gap of 40 rows; ``TI`` every row with a NaN stretch of 12 rows; ``PI`` every third row (its own
    median interval 30 s) with jittered times; ``QI`` (input) missing for 30 rows at 500.
    """
    rng = np.random.default_rng(3)
    t = 10.0 * np.arange(ROWS)
    fi = 5.0 + rng.normal(size=ROWS)
    fi[:7] = np.nan
    fi[300:320] = 0.2
    fi[410:450] = np.nan
    ti = 300.0 + np.cumsum(rng.normal(size=ROWS)) * 0.1
    ti[200:212] = np.nan
    pi = 1e5 + rng.normal(size=ROWS) * 50.0
    pi[np.arange(ROWS) % 3 != 0] = np.nan
    pi[150:190] = np.nan
    qi = 2.0 + rng.normal(size=ROWS) * 0.1
    qi[500:530] = np.nan
    time = t + np.where(np.arange(ROWS) % 7 == 3, 0.5, 0.0)  # some rows off the 10 s beat
    frame = pd.DataFrame({"time": time, "FI": fi, "QI": qi, "TI": ti, "PI": pi, "LI": 0.5 + 0.01 * ti})
    path = tmp_path / "m.csv"
    frame.to_csv(path, index=False, na_rep="", float_format="%.17g")
    rules = DataRules(stoppage=StoppageRule(tag="FI", below=1.0, settle=55.0), max_gap=max_gap,
                      heartbeat={"PI": 60.0} if heartbeat else {})
    return Spec(path=tmp_path / "spec.toml", twin=tmp_path / "twin.fmu", measurements=path, sample_time=10.0,
                inputs={"FI": "u", "QI": "q"}, outputs={"TI": "y", "PI": "p", "LI": "level"}, data=rules,
                windows={"training": (0.0, 3000.0), "validation": (3000.0, 7000.0)})


@pytest.fixture(autouse=True)
def _small_chunks(monkeypatch: pytest.MonkeyPatch) -> None:
    """Chunks and index entries much shorter than the file: their boundaries fall inside the stretches."""
    monkeypatch.setattr(data_table, "CHUNK_ROWS", 64)  # where the chunked reader reads it
    monkeypatch.setattr(stream, "INDEX_EVERY", 16)


def _assert_rows(view: MeasurementView, whole: MeasurementView, a: int, b: int) -> None:
    sl = slice(a, b)
    assert np.array_equal(view.grid, whole.grid[sl])
    for tag, values in whole.samples.items():
        assert np.array_equal(view.samples[tag], values[sl], equal_nan=True), tag
    for name in ("stopped", "input_gap", "stoppage_unknown"):
        assert np.array_equal(getattr(view, name), getattr(whole, name)[sl]), name
    for tag, mask in whole.scored.items():
        assert np.array_equal(view.scored[tag], mask[sl]), tag
    assert list(view.inputs.columns) == list(whole.inputs.columns)
    for column in whole.inputs.columns:
        assert np.array_equal(view.inputs[column].to_numpy(), whole.inputs[column].to_numpy()[sl]), column
    assert view.max_gap == whole.max_gap and view.window == whole.window and view.t0 == whole.t0


@pytest.mark.parametrize("window", ["all", "validation"])
@pytest.mark.parametrize("max_gap", [None, 25.0])
def test_every_stretch_is_the_whole_views_rows(tmp_path: Path, window: str, max_gap: float | None) -> None:
    spec = _case(tmp_path, max_gap=max_gap)
    whole = MeasurementView.from_spec(spec, window, skip=600.0)
    windows = WindowedMeasurements.open(spec, window, skip=600.0, directory=tmp_path, stats_tags=["TI", "LI"],
                                        rows_per_window=50)
    assert windows is not None
    n = whole.grid.size
    assert windows.n_rows == n and np.array_equal(np.asarray(windows.grid), whole.grid)
    # forwards with overlaps (as a run goes), then back to the start, then a jump past gaps (a resume)
    # (each input's gaps start inside the stretch before one: its hold comes from that stretch's rows)
    for a, b in [(0, 7), (5, 60), (58, 140), (139, 420), (300, 305), (400, 430), (425, 470), (480, 510),
                 (505, 540), (0, n), (9, 11), (450, 520), (n - 3, n)]:
        _assert_rows(windows.view(a, b), whole, a, b)
    # the whole-run figures: percentiles and missing inputs counted on the whole view's arrays
    for tag in ("TI", "LI"):
        values = whole.samples[tag]
        ok = values[np.isfinite(values)]
        assert windows.percentiles(tag) == (ok.size, *np.percentile(ok, [1.0, 99.0]))
    for tag in spec.inputs:
        assert windows.input_missing[tag] == int(np.count_nonzero(~np.isfinite(whole.samples[tag])))
    assert windows.max_step == float(np.min(np.diff(whole.grid)))
    windows.close()


def test_heartbeat_tags_and_the_long_form_take_the_whole_view(tmp_path: Path) -> None:
    # sample-and-hold looks at the next archived value however far away: no window is exact
    assert WindowedMeasurements.open(_case(tmp_path, heartbeat=True), directory=tmp_path) is None
    spec = _case(tmp_path)
    frame = pd.read_csv(spec.measurements)
    long = frame.melt(id_vars="time", var_name="tag", value_name="value").dropna()
    long.to_csv(spec.measurements, index=False)
    assert WindowedMeasurements.open(spec, directory=tmp_path) is None
