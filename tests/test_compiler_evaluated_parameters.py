"""Real parameters with ``annotation(Evaluate = true)`` (issue 35: MSL
``Analog.Examples.HeatingNPN_NORGate`` sets every capacitance to ``CapVal = 0`` with Evaluate = true):
the equations see their value, as the tools that evaluate them do, so a capacitor with C = 0 carries
no current and its voltage is no state; a variable that an equation sets to 0 through such a
parameter (a junction capacitance ``c = C*(1 + v^2)``) is 0 in the others. The same model with C
left tunable is an RC circuit. Expectations: closed forms (v = u; the RC circuit's response to a
sine from scipy)."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

MODEL = """model ZeroCap "a source u = sin(t) through R into a capacitance c = C (1 + v^2)"
  parameter Real C = CVALUE annotation(Evaluate = EVALUATE);
  parameter Real R = 2;
  Real v(start = 0, fixed = FIXED);
  Real c;
  Real i;
  Real x(start = 1, fixed = true);
equation
  der(x) = -x;
  c = C*(1 + v^2);
  i = c*der(v);
  sin(time) - v = R*i;
end ZeroCap;
"""


def _compile(tmp_path, c: str, evaluate: str, fixed: str):
    src = tmp_path / "ZeroCap.mo"
    src.write_text(MODEL.replace("CVALUE", c).replace("EVALUATE", evaluate).replace("FIXED", fixed))
    return compile_model(src, "ZeroCap", backend="embedded", output=tmp_path / "z.fmu")


def test_an_evaluated_zero_capacitance_leaves_no_state(tmp_path):
    res = _compile(tmp_path, "0", "true", "false")
    assert res.states == 1  # x only
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=2.0, output_interval=0.1, output=["v", "i", "c", "x"])
    assert np.allclose(out["v"], np.sin(out["time"]), atol=1e-9)
    assert np.allclose(out["i"], 0.0, atol=1e-12) and np.allclose(out["c"], 0.0, atol=1e-12)
    assert np.allclose(out["x"], np.exp(-out["time"]), rtol=1e-4)


def test_a_capacitance_not_evaluated_is_a_state(tmp_path):
    res = _compile(tmp_path, "0.5", "false", "true")
    assert res.states == 2
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=2.0, output_interval=0.1, output=["v"],
                            relative_tolerance=1e-9)

    def rhs(t, y):  # R C (1 + v^2) dv/dt = sin(t) - v
        return [(np.sin(t) - y[0]) / (2.0 * 0.5 * (1 + y[0] ** 2))]

    ref = solve_ivp(rhs, (0, 2), [0.0], t_eval=out["time"], rtol=1e-10, atol=1e-12)
    assert np.allclose(out["v"], ref.y[0], atol=1e-5)
