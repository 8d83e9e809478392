"""Property-based fuzzing of CSV reading (issue 13): a table within its contract, or one DataError.

The oracle for generated tables is computed here in plain Python from the rows
written: ``read_table(allow_nan=False)`` must accept exactly the tables whose
times are finite and strictly increasing (any magnitude: the measurement view
bounds the grid) and whose values are finite and within
``data.MAX_MAGNITUDE``; what it returns must equal what was written.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trackingbox.data import MAX_MAGNITUDE, read_table
from trackingbox.errors import DataError

FUZZ = settings(max_examples=60, deadline=10000, suppress_health_check=[HealthCheck.function_scoped_fixture])

NUMBERS = st.one_of(
    st.floats(min_value=-1e6, max_value=1e6, allow_nan=False),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e308, -1e308, 1e151, -1e151, 1e150, 0.0, -0.0]),
)


def _cell(x: float) -> str:
    return "nan" if math.isnan(x) else ("inf" if x == math.inf else "-inf" if x == -math.inf else repr(x))


def _expected_ok(rows: list[tuple[float, float]]) -> bool:
    if not rows:
        return False
    times = [t for t, _ in rows]
    values = [v for _, v in rows]
    if not all(math.isfinite(t) for t in times) or any(b <= a for a, b in zip(times, times[1:])):
        return False
    return all(math.isfinite(v) and abs(v) <= MAX_MAGNITUDE for v in values)


@FUZZ
@pytest.mark.filterwarnings("error::RuntimeWarning")  # times near the float limits: no overflow warning either
@given(rows=st.lists(st.tuples(NUMBERS, NUMBERS), max_size=12))
def test_read_table_accepts_exactly_the_valid_tables(tmp_path: Path, rows: list[tuple[float, float]]) -> None:
    path = tmp_path / "in.csv"
    path.write_text("time,u\n" + "".join(f"{_cell(t)},{_cell(v)}\n" for t, v in rows))
    try:
        table = read_table(path, allow_nan=False)
    except DataError as exc:
        assert not _expected_ok(rows), f"refused a valid table: {exc}"
        assert "in.csv" in str(exc) and len(str(exc)) < 4000
        return
    assert _expected_ok(rows), "accepted an invalid table"
    assert np.array_equal(table["time"].to_numpy(), np.array([t for t, _ in rows]) - 0.0)
    assert np.array_equal(table["u"].to_numpy(), np.array([v for _, v in rows]))


@FUZZ
@given(data=st.binary(max_size=600))
def test_any_bytes_give_a_table_or_one_data_error(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / "in.csv"
    path.write_bytes(data)
    try:
        table = read_table(path, allow_nan=False)
    except DataError as exc:
        assert "in.csv" in str(exc) and len(str(exc)) < 4000
        return
    t = table["time"].to_numpy(dtype=float)
    assert np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)
    assert not table.drop(columns="time").isna().to_numpy().any()


@FUZZ
@given(text=st.text(max_size=300))
def test_any_text_gives_a_table_or_one_data_error(tmp_path: Path, text: str) -> None:
    path = tmp_path / "in.csv"
    path.write_text("time,u\n0,1\n" + text, encoding="utf-8")
    try:
        read_table(path, allow_nan=False)
    except DataError as exc:
        assert "in.csv" in str(exc) and len(str(exc)) < 4000


def test_a_megabyte_cell_is_not_echoed(tmp_path: Path) -> None:
    path = tmp_path / "in.csv"
    path.write_text("time,u\n0,1\n10," + "x" * (1 << 20) + "\n")
    try:
        read_table(path, allow_nan=False)
    except DataError as exc:
        assert "line 3" in str(exc) and len(str(exc)) < 400
    else:
        raise AssertionError("a non-numeric cell was accepted")
