"""``pre(y)`` of a continuous-time variable in a when-clause is its left limit (MLS 3.7.5; issue 35:
the MSL's ``TriggeredTrapezoid``, PumpingSystem's speed command, jumped to its amplitude instead of
ramping from ``pre(y)``). Checked against hand-worked values."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

LEFT = """
model LeftLimit "pre() of algebraic variables that jump at the very event that reads them"
  Real x(start = 0, fixed = true);
  Real y "jumps by 10 where x passes 1";
  Real w "jumps by 10 at each tick: k changes in the same when-clause";
  discrete Real k(start = 0, fixed = true);
  discrete Real at(start = -1, fixed = true) "y just before x passed 1";
  discrete Real before(start = -1, fixed = true) "w just before the last tick";
equation
  der(x) = 1;
  y = if x > 1 then 10 + x else x;
  w = 2*x + 10*k;
  when x > 1 then
    at = pre(y);
  end when;
  when sample(0.5, 1) then
    k = pre(k) + 1;
    before = pre(w);
  end when;
end LeftLimit;
"""

TRAPEZOID = """
model Trap "the MSL's TriggeredTrapezoid switched on at 2 s and off at 3.5 s, mid-ramp"
  Modelica.Blocks.Logical.TriggeredTrapezoid trap(rising = 3, falling = 2, amplitude = 1200, offset = 0.001);
equation
  trap.u = time >= 2 and time < 3.5;
end Trap;
"""


def test_pre_of_an_algebraic_variable_is_its_value_just_before_the_event(tmp_path):
    src = tmp_path / "LeftLimit.mo"
    src.write_text(LEFT)
    fmu = compile_model(src, "LeftLimit", backend="embedded", output=tmp_path / "l.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=4.2, output_interval=0.1, output=["at", "before", "k", "y"],
                            relative_tolerance=1e-8, record_events=False)
    t = out["time"]
    # y = x = t up to t = 1 (where x passes 1): y's left limit there is 1, not 10 + 1
    assert np.allclose(out["at"][t > 1.05], 1.0, atol=1e-6)
    assert np.all(out["at"][t < 0.95] == -1)
    assert np.allclose(out["y"][t > 1.05], 10 + t[t > 1.05], atol=1e-6)
    # the n-th tick at t_n = n - 0.5 (n = 1, 2, ...): w just before it is 2 t_n + 10 (n - 1)
    n = np.floor(t + 0.5)
    settled = np.abs(t + 0.5 - np.round(t + 0.5)) > 0.05
    assert np.array_equal(out["k"][settled], n[settled])
    expect = np.where(n > 0, 2 * (n - 0.5) + 10 * (n - 1), -1.0)
    assert np.allclose(out["before"][settled], expect[settled], atol=1e-6)


def test_a_triggered_trapezoid_ramps_from_where_it_was(tmp_path):
    need_msl()
    src = tmp_path / "Trap.mo"
    src.write_text(TRAPEZOID)
    fmu = compile_model(src, "Trap", backend="embedded", output=tmp_path / "t.fmu", libraries=[MSL]).fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=8, output_interval=0.05, output=["trap.y"],
                            relative_tolerance=1e-8, record_events=False)
    t = out["time"]
    # hand-worked: up at 1200/3 = 400 per s from 0.001 at t = 2; at 3.5 it is 600.001 and falls at
    # 1200/2 = 600 per s from there, back to 0.001 at t = 4.5 (not from the amplitude: 1200.001)
    expect = np.interp(t, [0, 2, 3.5, 4.5, 8], [0.001, 0.001, 600.001, 0.001, 0.001])
    assert np.allclose(out["trap.y"], expect, atol=1e-6 * 1200)
