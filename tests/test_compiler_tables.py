"""The MSL's table blocks in the embedded compiler (issue 35, item 2): CombiTimeTable and CombiTable1Dv,
compiled from MSL 4.0.0 without their C sources, checked against interpolation computed here with
numpy (constant and linear segments, extrapolation, startTime, shiftTime, periodic tables)."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

TABLE = [[0.0, 1.0], [1.0, 3.0], [1.0, 5.0], [2.5, 2.0], [4.0, 2.0]]  # a jump at t = 1

MODEL = """
model Tables
  import Modelica.Blocks.Types.{Smoothness, Extrapolation};
  Modelica.Blocks.Sources.CombiTimeTable linear(table = %(T)s, smoothness = Smoothness.LinearSegments,
    extrapolation = Extrapolation.LastTwoPoints);
  Modelica.Blocks.Sources.CombiTimeTable stairs(table = %(T)s, smoothness = Smoothness.ConstantSegments,
    extrapolation = Extrapolation.HoldLastPoint, startTime = 0.5, offset = {10});
  Modelica.Blocks.Sources.CombiTimeTable shifted(table = %(T)s, smoothness = Smoothness.LinearSegments,
    extrapolation = Extrapolation.HoldLastPoint, shiftTime = 0.75);
  Modelica.Blocks.Sources.CombiTimeTable periodic(table = [0, 1; 1, 2; 3, 0],
    smoothness = Smoothness.ConstantSegments, extrapolation = Extrapolation.Periodic);
  Modelica.Blocks.Tables.CombiTable1Dv oneD(table = [0, 0, 1; 2, 4, 1; 3, 4, 7],
    smoothness = Smoothness.LinearSegments, extrapolation = Extrapolation.LastTwoPoints);
  Real integral(start = 0, fixed = true) "of the constant-segment table: piecewise linear";
equation
  oneD.u = {1.5*time, 1.5*time};
  der(integral) = stairs.y[1];
  annotation(experiment(StopTime = 7));
end Tables;
""" % {"T": "[" + "; ".join(f"{a}, {b}" for a, b in TABLE) + "]"}


def _constant(t, table, hold=True):
    ts = np.array([r[0] for r in table])
    ys = np.array([r[1] for r in table])
    idx = np.searchsorted(ts, t, side="right") - 1
    return ys[np.clip(idx, 0, len(ys) - 1)]


def _linear(t, table):
    """Linear segments, LastTwoPoints extrapolation, the jump at equal times (after it at t = 1)."""
    out = []
    for x in np.atleast_1d(t):
        rows = [r for r in table]
        if x >= rows[-1][0]:
            (t0, y0), (t1, y1) = rows[-2], rows[-1]
        else:
            k = max(i for i, r in enumerate(rows) if r[0] <= x) if x >= rows[0][0] else 0
            (t0, y0), (t1, y1) = rows[k], rows[k + 1]
            if t1 == t0:
                out.append(y1)
                continue
        out.append(y0 + (y1 - y0) * (x - t0) / (t1 - t0))
    return np.array(out)


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    need_msl()
    d = tmp_path_factory.mktemp("tables")
    (d / "Tables.mo").write_text(MODEL)
    res = compile_model(d / "Tables.mo", "Tables", backend="embedded", output=d / "t.fmu", libraries=[MSL])
    return fmpy.simulate_fmu(str(res.fmu), stop_time=7.0, output_interval=0.05, relative_tolerance=1e-9,
                             record_events=False,
                             output=["linear.y[1]", "stairs.y[1]", "shifted.y[1]", "periodic.y[1]",
                                     "oneD.y[1]", "oneD.y[2]", "integral"])


def _away_from(t, points, tol=1e-6):
    return np.all(np.abs(t[:, None] - np.asarray(points)[None, :]) > tol, axis=1)


def test_linear_segments_with_a_jump_and_extrapolation(result):
    t = result["time"]
    ok = _away_from(t, [1.0])
    assert np.allclose(result["linear.y[1]"][ok], _linear(t[ok], TABLE), atol=1e-9)


def test_constant_segments_after_the_start_time_plus_offset(result):
    t = result["time"]
    # shiftTime defaults to startTime: the table is read at t - 0.5 from t = 0.5 on
    ok = _away_from(t, [0.5, 1.5, 3.0, 4.5])
    expect = np.where(t < 0.5, 10.0, 10.0 + _constant(t - 0.5, TABLE))
    assert np.allclose(result["stairs.y[1]"][ok], expect[ok], atol=1e-12)
    # its integral: exact where the solver stopped at every table point (time events)
    grid = np.linspace(0, 7, 70001)
    vals = np.where(grid < 0.5, 10.0, 10.0 + _constant(grid - 0.5, TABLE))
    integral = np.concatenate([[0], np.cumsum((vals[1:] + vals[:-1]) / 2 * np.diff(grid))])
    assert np.allclose(result["integral"], np.interp(t, grid, integral), atol=2e-3)


def test_shift_time_moves_the_table(result):
    t = result["time"]
    ok = _away_from(t, [1.75])
    hold = np.clip(t - 0.75, 0.0, 4.0)
    assert np.allclose(result["shifted.y[1]"][ok], _linear(hold, TABLE)[ok], atol=1e-9)


def test_a_periodic_table_repeats(result):
    t = result["time"]
    ok = _away_from(t, [1.0, 3.0, 4.0, 6.0, 7.0])
    expect = _constant(np.mod(t, 3.0), [[0, 1], [1, 2], [3, 0]])
    assert np.allclose(result["periodic.y[1]"][ok], expect[ok], atol=1e-12)


def test_a_one_dimensional_table_interpolates_its_input(result):
    u = 1.5 * result["time"]
    table = np.array([[0, 0, 1], [2, 4, 1], [3, 4, 7]], dtype=float)
    for col, name in ((1, "oneD.y[1]"), (2, "oneD.y[2]")):
        rows = [[a, b] for a, b in zip(table[:, 0], table[:, col])]
        assert np.allclose(result[name], _linear(u, rows), atol=1e-9)


def test_a_table_read_from_a_file_is_refused(tmp_path):
    if not (MSL / "package.mo").is_file():
        pytest.skip(f"the Modelica Standard Library is not at {MSL}")
    src = tmp_path / "FromFile.mo"
    src.write_text('model FromFile\n  Modelica.Blocks.Sources.CombiTimeTable t(tableOnFile = true, '
                   'tableName = "tab1", fileName = "data.txt");\nend FromFile;\n')
    with pytest.raises(UnsupportedConstructError, match="read from a file|table constructor"):
        compile_model(src, "FromFile", backend="embedded", output=tmp_path / "f.fmu", libraries=[MSL])
