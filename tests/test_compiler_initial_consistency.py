"""An overdetermined initialisation problem whose extra initial equations the model's equations already
fix (issue 35: Modelica.Fluid's ``mediums.p = ps_start`` for a pipe volume whose pressure a boundary at
its port prescribes, ``boundary.p = ps_start[1]`` once substituted): such an equation, in which only
parameters are left, is dropped from the problem and checked as a consistency condition on the
parameters; inconsistent parameters stop the run naming the equation, never give a silent result."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import CompileError

pytestmark = pytest.mark.compile

REDUNDANT = """model E
  parameter Real p0 = 2;
  parameter Real p_start = 2;
  parameter Real c(fixed = false) "an unknown of the initialisation problem, never a condition";
  Real x(start = 0);
  Real y;
initial equation
  x = 1;
  y = p_start "fixed already by y = p0: consistent where p_start = p0";
  c = 2*p0;
equation
  der(x) = -c*x/4;
  y = p0;
end E;
"""


@pytest.fixture
def fmu(tmp_path):
    src = tmp_path / "E.mo"
    src.write_text(REDUNDANT)
    return compile_model(src, "E", backend="embedded", output=tmp_path / "e.fmu").fmu


def test_a_redundant_consistent_initial_equation_is_dropped(fmu):
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.25, output=["x", "y", "c"],
                            relative_tolerance=1e-8)
    assert np.allclose(out["c"], 4.0)  # c = 2 p0
    assert np.allclose(out["x"], np.exp(-out["time"]), rtol=1e-5)  # x(0) = 1, der(x) = -c x/4 = -x
    assert np.allclose(out["y"], 2.0)


def test_inconsistent_parameters_stop_the_run_naming_the_equation(fmu):
    logged: list[str] = []

    def logger(*args):
        logged.append(" ".join(a.decode() if isinstance(a, bytes) else str(a) for a in args))

    with pytest.raises(Exception, match="fmi3ExitInitializationMode failed"):
        fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.5, start_values={"p_start": 3.0},
                          logger=logger)
    assert any("assert failed at t = 0 s: initial equation" in m and "holds only for consistent parameters" in m
               for m in logged), logged


def test_a_redundant_equation_with_a_variable_left_is_still_an_error(tmp_path):
    src = tmp_path / "F.mo"
    src.write_text(REDUNDANT.replace("model E", "model F").replace("end E;", "end F;")
                   .replace("y = p_start", "y = x + p_start"))
    with pytest.raises(CompileError, match="initialisation problem of F has 3 equations for 2 unknowns"):
        compile_model(src, "F", backend="embedded", output=tmp_path / "f.fmu")


NO_SOLUTION = """model G "x^2 + p = 0 has no real root for p > 0: its smallest residual is p, at x = 0"
  parameter Real p = 0.5;
  Real x(start = 0.3);
initial equation
  x^2 + p = 0;
equation
  der(x) = -x;
end G;
"""


def test_an_initial_equation_without_solution_stops_the_run_naming_its_residual(tmp_path):
    src = tmp_path / "G.mo"
    src.write_text(NO_SOLUTION)
    fmu = compile_model(src, "G", backend="embedded", output=tmp_path / "g.fmu").fmu
    logged: list[str] = []

    def logger(*args):
        logged.append(" ".join(a.decode() if isinstance(a, bytes) else str(a) for a in args))

    with pytest.raises(Exception, match="fmi3ExitInitializationMode failed"):
        fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.5, logger=logger)
    failed = [m for m in logged if "initialisation failed" in m]
    assert failed, logged
    # the residual named is x^2 + p at the solve's end: at least p (0.5), and finite, or the unknown is named
    import re
    m = re.search(r"residual ([-+0-9.eE]+|nan|inf) of the", failed[0])
    if m:
        assert float(m.group(1)) >= 0.5 - 1e-9
    else:
        assert "their solve gives x = " in failed[0], failed[0]
