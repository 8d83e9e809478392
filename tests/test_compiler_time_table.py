"""``Modelica.Blocks.Sources.TimeTable``: its function ``getInterpolationCoefficients`` searches the
table's grid in a while loop on a condition that varies with time, which the embedded backend cannot
translate; it is read with an equivalent for loop (:data:`trackingbox.compiler.rewrite.LIBRARY_BODIES`).
Checked against numpy's piecewise-linear interpolation of the tables, worked out by hand where the
table jumps (two rows at one time) and before its start time."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model
from trackingbox.compiler.rewrite import replace_library_bodies

pytestmark = pytest.mark.compile


def _away(t: np.ndarray, edges) -> np.ndarray:
    return np.min(np.abs(t[:, None] - np.asarray(edges, float)[None, :]), axis=1) > 1e-6


def test_get_interpolation_coefficients_is_replaced_keeping_lines_and_offsets():
    path = need_msl("Blocks", "Sources.mo")
    data = path.read_bytes()
    new, done = replace_library_bodies(data)
    assert [name for name, _ in done] == ["Modelica.Blocks.Sources.TimeTable.getInterpolationCoefficients"]
    assert len(new) == len(data) and new.count(b"\n") == data.count(b"\n")
    head = data.find(b"function getInterpolationCoefficients")
    end = data.find(b"end getInterpolationCoefficients;", head)
    assert b"while" in data[head:end] and b"while" not in new[head:end]
    assert new[:head] == data[:head] and new[end:] == data[end:]


def test_msl_interaction1_time_table_follows_its_table(tmp_path):
    """Interaction1's timeTable: table [0, 0; 1, 2.1; 2, 4.2; 3, 6.3; 4, 4.2; 6, 2.1; 6, 2.1], held at
    its last value after t = 6 s (the last interval has no length)."""
    need_msl()
    fmu = compile_model(MSL, "Modelica.Blocks.Examples.Interaction1", backend="embedded",
                        output=tmp_path / "i1.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=10.0, output_interval=0.05, output=["timeTable.y"])
    t = out["time"]
    expect = np.interp(t, [0, 1, 2, 3, 4, 6], [0, 2.1, 4.2, 6.3, 4.2, 2.1])
    assert np.max(np.abs(out["timeTable.y"] - expect)) < 1e-6  # event instants located to ~1e-9 s


def test_time_table_with_a_jump_an_offset_and_a_start_time(tmp_path):
    """table [0, 0; 1, 1; 1, 3; 2, 3; 4, -1], offset 0.5, startTime 1: y = offset before t = 1, then
    the table read at t - 1 (shiftTime = startTime): a ramp to 1, a jump to 3 at t = 2, flat to t = 3,
    down to -1 at t = 5, and from there extrapolated along the last interval (slope -2)."""
    need_msl()
    src = tmp_path / "TT.mo"
    src.write_text("model TT\n  Modelica.Blocks.Sources.TimeTable tt(table = [0, 0; 1, 1; 1, 3; 2, 3; 4, -1], "
                   "offset = 0.5, startTime = 1);\nend TT;\n")
    fmu = compile_model(src, "TT", backend="embedded", output=tmp_path / "tt.fmu", libraries=[MSL]).fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=6.0, output_interval=0.05, output=["tt.y"])
    t = out["time"]
    s = t - 1.0
    table = np.where(s < 1, s, np.where(s < 2, 3.0, 3.0 - 2.0 * (s - 2)))
    expect = 0.5 + np.where(t < 1, 0.0, table)
    away = _away(t, [1.0, 2.0])
    assert away.sum() > 100
    assert np.max(np.abs(out["tt.y"][away] - expect[away])) < 1e-6
