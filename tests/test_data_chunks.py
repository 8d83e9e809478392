"""read_table's chunked reading of long clean files: same values, same messages past the first chunk, less memory."""
from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import trackingbox.data as data
from trackingbox.data import read_table
from trackingbox.errors import DataError

ROWS = 3 * data.CHUNK_ROWS + 17  # several chunks and a short last one


def _write(path, rows=ROWS, cell=None, seed=0):
    """A wide CSV of *rows* rows (time every 10 s, two tags), values written with repr; *cell* = (row, tag, text)."""
    rng = np.random.default_rng(seed)
    t = 10.0 * np.arange(rows)
    a = 300.0 + rng.normal(size=rows)
    b = rng.normal(size=rows) * 1e-3
    lines = ["time,TI-1,FI-2"]
    for i in range(rows):
        cells = [repr(float(t[i])), repr(float(a[i])), repr(float(b[i]))]
        if cell is not None and cell[0] == i:
            cells[cell[1]] = cell[2]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return t, a, b


def test_values_are_the_written_floats_across_chunks(tmp_path):
    path = tmp_path / "m.csv"
    t, a, b = _write(path)
    df = read_table(path)
    assert list(df.columns) == ["time", "TI-1", "FI-2"]
    # repr round-trips exactly: the floats read must be the ones written, bit for bit
    assert np.array_equal(df["time"].to_numpy(), t)
    assert np.array_equal(df["TI-1"].to_numpy(), a)
    assert np.array_equal(df["FI-2"].to_numpy(), b)
    assert df.attrs["t0"] is None and df.attrs["source"] == str(path)


def test_empty_cells_past_the_first_chunk_are_nan_where_allowed(tmp_path):
    path = tmp_path / "m.csv"
    row = 2 * data.CHUNK_ROWS + 5
    _write(path, cell=(row, 1, ""))
    df = read_table(path, allow_nan=True)
    values = df["TI-1"].to_numpy()
    assert np.isnan(values[row]) and np.isfinite(np.delete(values, row)).all()
    with pytest.raises(DataError, match=rf"tag 'TI-1' in m.csv has 1 NaN value at {10 * row:g} s"):
        read_table(path)


@pytest.mark.parametrize("column, text, message", [
    (1, "abc", "tag 'TI-1' in m.csv has non-numeric values: 'abc' on line {line}"),
    (2, "inf", "tag 'FI-2' in m.csv has infinite values, first on line {line}"),
    (2, "1e200", "tag 'FI-2' in m.csv has values beyond +-1e+150 (their squares overflow), first 1e+200 on line {line}"),
])
def test_bad_cell_past_the_first_chunk_is_named_by_line(tmp_path, column, text, message):
    path = tmp_path / "m.csv"
    row = 2 * data.CHUNK_ROWS + 100  # data row 0 is line 2
    _write(path, cell=(row, column, text))
    with pytest.raises(DataError) as exc:
        read_table(path)
    assert str(exc.value) == message.format(line=row + 2)


def test_time_going_back_at_a_chunk_boundary_is_named(tmp_path):
    path = tmp_path / "m.csv"
    row = data.CHUNK_ROWS  # first row of the second chunk
    _write(path, cell=(row, 0, "5"))
    with pytest.raises(DataError) as exc:
        read_table(path)
    assert str(exc.value) == (f"column 'time' in m.csv goes backwards: line {row + 2} has 5 s after "
                              f"{10 * (row - 1):g} s on line {row + 1} (1 decrease in all)")


def test_reading_holds_floats_not_text(tmp_path):
    """Peak Python allocations while reading stay within three times the floats themselves.

    The whole-file text read held every cell as a Python string (about 60
    bytes each against 8 for a float): for this file its peak was 11 times the
    table's floats (measured with tracemalloc when the chunked read came in);
    the chunked read's is the floats, their chunk lists and one chunk of text.
    """
    path = tmp_path / "m.csv"
    rows = 32 * data.CHUNK_ROWS
    _write(path, rows=rows)
    floats = rows * 3 * 8
    tracemalloc.start()
    try:
        read_table(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 3 * floats, f"peak {peak / 2**20:.1f} MiB for {floats / 2**20:.1f} MiB of floats"


@pytest.mark.parametrize("times", [("inf",), ("0", "inf"), ("-inf", "0", "10")])
def test_an_infinite_time_is_refused_with_its_line(tmp_path: Path, times: tuple[str, ...]) -> None:
    # found by the CSV fuzz test: a single row (or a last row) at time inf passed the order check
    path = tmp_path / "m.csv"
    path.write_text("time,u\n" + "".join(f"{t},1.0\n" for t in times))
    line = 2 + next(i for i, t in enumerate(times) if "inf" in t)
    with pytest.raises(DataError, match=rf"column 'time' in m\.csv has 1 infinite value, first on line {line}"):
        read_table(path, allow_nan=False)
