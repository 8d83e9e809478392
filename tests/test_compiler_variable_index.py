"""An array element read with an Integer variable as its index (``expr[firstActiveIndex]`` in the
MSL's ``Blocks.Math.MultiSwitch``), and ``Modelica.Math.BooleanVectors.firstTrueIndex`` (a ``return``
inside a for loop, which rumoca 0.10.2 refuses; read with an equivalent body, see
:data:`trackingbox.compiler.rewrite.LIBRARY_BODIES`). Checked against values worked out by hand from
the models' definitions: a counter stepping through a vector and a matrix, and the MSL's
``Blocks.Examples.RealNetwork1``, whose switch follows two Boolean pulses of known periods."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model
from trackingbox.compiler.rewrite import replace_library_bodies

pytestmark = pytest.mark.compile

COUNTER = """model Counter
  parameter Real e[3] = {10, 20, 30};
  parameter Real m[2, 3] = [1, 2, 3; 4, 5, 6];
  Integer i(start = 1, fixed = true);
  Real y;
  Real z;
  Real col[2];
  Real x(start = 0, fixed = true);
equation
  when sample(0.5, 1) then
    i = mod(pre(i), 3) + 1;
  end when;
  y = e[i];
  z = m[2, i];
  col = m[:, i];
  der(x) = e[i];
end Counter;
"""


def test_an_integer_variable_picks_vector_and_matrix_elements(tmp_path):
    src = tmp_path / "Counter.mo"
    src.write_text(COUNTER)
    fmu = compile_model(src, "Counter", backend="embedded", output=tmp_path / "c.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=4.0, output_interval=0.25, relative_tolerance=1e-8,
                            output=["i", "y", "z", "col[1]", "col[2]", "x"])
    t = out["time"]
    inside = np.abs((t - 0.5) - np.round(t - 0.5)) > 1e-6  # away from the sample instants
    # i: 1 before t = 0.5, then 2, 3, 1, 2 ... one step per second
    i = np.where(t < 0.5, 1, (np.floor(t - 0.5).astype(int) + 1) % 3 + 1)
    assert np.array_equal(out["i"][inside], i[inside])
    assert np.allclose(out["y"][inside], 10.0 * i[inside])
    assert np.allclose(out["z"][inside], 3.0 + i[inside])
    assert np.allclose(out["col[1]"][inside], i[inside]) and np.allclose(out["col[2]"][inside], 3.0 + i[inside])
    # x integrates e[i]: 10 * 0.5, then 20, 30, 10 per second
    expect = 0.5 * 10 + 20 + 30 + 10 + 0.5 * 20  # t = 4: 0.5 s at 10, a second each at 20, 30, 10, 0.5 s at 20
    assert out["x"][-1] == pytest.approx(expect, rel=1e-6)


def test_first_true_index_is_read_without_its_return():
    path = need_msl("Math", "BooleanVectors.mo")
    data = path.read_bytes()
    new, done = replace_library_bodies(data)
    assert [name for name, _ in done] == ["Modelica.Math.BooleanVectors.firstTrueIndex"]
    assert len(new) == len(data) and new.count(b"\n") == data.count(b"\n")
    head = data.find(b"function firstTrueIndex")
    end = data.find(b"end firstTrueIndex;", head)
    assert b"return;" in data[head:end] and b"return;" not in new[head:end]
    assert new[:head] == data[:head] and new[end:] == data[end:]


def test_msl_real_network_switch_follows_its_pulses(tmp_path):
    """RealNetwork1's multiSwitch: u = {booleanPulse1 (period 1 s, width 50 %), booleanPulse2 (period
    2 s, width 80 %)}, expr = {4, 6}, y_default = 2: y = 4 while the first pulse is high, else 6 while
    the second is, else 2."""
    need_msl()
    fmu = compile_model(MSL, "Modelica.Blocks.Examples.RealNetwork1", backend="embedded",
                        output=tmp_path / "rn.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=10.0, output_interval=0.05, output=["multiSwitch.y"])
    t = out["time"]
    p1 = np.mod(t, 1.0) < 0.5
    p2 = np.mod(t, 2.0) < 1.6
    expect = np.where(p1, 4.0, np.where(p2, 6.0, 2.0))
    edges = np.concatenate([np.arange(0, 10.01, 0.5), np.arange(1.6, 10, 2.0)])
    away = np.min(np.abs(t[:, None] - edges[None, :]), axis=1) > 1e-6
    assert away.sum() > 100 and set(expect[away]) == {2.0, 4.0, 6.0}
    assert np.array_equal(out["multiSwitch.y"][away], expect[away])
