"""Integer and Boolean parameters evaluated at translation (:mod:`trackingbox.compiler.structural_params`).

* ``Modelica.Blocks.Continuous.Derivative``'s ``zeroGain = abs(k) < eps``, a Boolean bound to the
  Real parameter ``k``: evaluated with k's value, the block's output is the derivative filter's
  closed form for a ramp input; started with ``k = 0`` the FMU stops naming the parameter instead of
  computing with a gain it was not compiled for.
* An Integer ``parameter (fixed = false)`` given by an initial equation takes its value.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl

MODEL = """
model Deriv
  parameter Real k = 2;
  parameter Integer base = 7;
  final parameter Integer n(fixed = false);
  Modelica.Blocks.Sources.Ramp ramp(height = 1, duration = 10);
  Modelica.Blocks.Continuous.Derivative d(k = k, T = 0.5,
    initType = Modelica.Blocks.Types.Init.InitialOutput);
  Real y = d.y;
  Real m = n;
  parameter Real a = 1;
  parameter Boolean big = a > 0.5;
  Real z(start = 0, fixed = true);
initial equation
  n = 3*base;
equation
  connect(ramp.y, d.u);
  der(z) = if big then 1 else -1;
end Deriv;
"""


def test_boolean_bound_to_a_real_parameter_is_evaluated_and_kept(tmp_path, capfd):
    import fmpy

    from trackingbox.compiler import compile_model

    need_msl("Blocks", "Continuous.mo")
    src = tmp_path / "Deriv.mo"
    src.write_text(MODEL)
    fmu = tmp_path / "Deriv.fmu"
    compile_model(src, "Deriv", backend="embedded", output=fmu, libraries=[MSL])
    res = fmpy.simulate_fmu(str(fmu), stop_time=2.0, output_interval=0.5, output=["y", "m", "z"],
                            relative_tolerance=1e-9)
    # y(0) = 0; x' = (u - x)/T with u = t/10: y = k/T (u - x) = k/10 (1 - exp(-t/T))
    expected = 2 / 10 * (1 - np.exp(-res["time"] / 0.5))
    np.testing.assert_allclose(res["y"], expected, atol=1e-4)
    assert res["m"][0] == 21
    np.testing.assert_allclose(res["z"], res["time"], atol=1e-9)
    again = fmpy.simulate_fmu(str(fmu), stop_time=1.0, start_values={"a": 0.7}, output=["z"])
    assert again["z"][-1] == pytest.approx(1.0)  # a > 0.5 still: the same branch
    with pytest.raises(Exception, match="failed"):  # the FMU stops: see the message in the log
        fmpy.simulate_fmu(str(fmu), stop_time=1.0, start_values={"a": 0.2})
    assert re.search(r"parameter big was evaluated to 1 when the model was compiled \(from a\)", capfd.readouterr().out)
    with pytest.raises(Exception, match="failed"):  # k = 0 would make zeroGain true: stopped too
        fmpy.simulate_fmu(str(fmu), stop_time=1.0, start_values={"k": 0.0})
    assert math.isfinite(float(res["y"][-1]))

