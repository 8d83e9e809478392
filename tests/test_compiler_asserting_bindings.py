"""A parameter bound to a call of a function that asserts (MLS 12.4; the MSL's
``Vectors.interpolate`` in ``LossyGear``'s bindings): rumoca 0.10.2 counts the assert its evaluation
of the binding reaches as one more equation ("unbalanced model: 2 equations, 1 unknowns"), so the
front end is run again on a copy in which such a parameter is ``fixed = false`` and its binding an
initial equation (:func:`trackingbox.compiler.rewrite.computed_parameter_bindings`). Checked against
the interpolation worked out by hand, and the assert still stops a table the function refuses."""
from __future__ import annotations

import fmpy
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model
from trackingbox.compiler.rewrite import computed_parameter_bindings

pytestmark = pytest.mark.compile


OWN = """package Own
  function g "linear interpolation on the last segment, asserting increasing abscissae"
    input Real x[:];
    input Real y[:];
    input Real u;
    output Real z;
  algorithm
    z := y[1];
    for k in 1:size(x, 1) - 1 loop
      assert(x[k + 1] > x[k], "abscissae must increase");
      z := y[k] + (y[k + 1] - y[k])*(u - x[k])/(x[k + 1] - x[k]);
    end for;
  end g;
  model M
    parameter Real tab[:, 2] = [0, 0.8; 1, 0.7];
  protected
    parameter Real p(unit = "1") = g(tab[:, 1], tab[:, 2], 0.25) "interpolated";
    parameter Real q = if p > 0.77 then 2*p else p;
  public
    Real s(start = 0, fixed = true);
  equation
    der(s) = q;
  end M;
end Own;
"""


def test_the_copy_declares_the_parameter_computed_and_keeps_every_line():
    new, lines = computed_parameter_bindings(OWN.encode(), frozenset({b"g"}))
    assert lines == [17]
    assert new.count(b"\n") == OWN.count("\n")
    line = new.split(b"\n")[16].decode()
    assert line.strip() == ('parameter Real p(fixed = false, unit = "1") "interpolated"; initial equation '
                            'p = g(tab[:, 1], tab[:, 2], 0.25); protected')
    # a function that does not assert leaves the text as it is
    assert computed_parameter_bindings(OWN.encode(), frozenset({b"h"})) == (OWN.encode(), [])


def test_a_binding_through_an_asserting_function_compiles_with_its_value(tmp_path):
    src = tmp_path / "Own.mo"
    src.write_text(OWN)
    fmu = compile_model(src, "Own.M", backend="embedded", output=tmp_path / "m.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=2.0)
    # p = 0.8 - 0.1*0.25 = 0.775 > 0.77, so q = 1.55 and s(2) = 3.1
    assert out["s"][-1] == pytest.approx(3.1, rel=1e-9)
    messages: list[str] = []
    with pytest.raises(Exception, match="fmi3ExitInitializationMode"):
        fmpy.simulate_fmu(str(fmu), stop_time=1.0, start_values={"tab[2,1]": -1.0},
                          logger=lambda *a: messages.append(str(a[-1])))
    assert any("abscissae must increase" in m for m in messages), messages


def test_msl_interpolate_in_a_parameter_binding(tmp_path):
    need_msl()
    src = tmp_path / "Q.mo"
    src.write_text("model Q\n  parameter Real tab[:, 2] = [0, 0.8; 1, 0.7; 2, 0.4];\n"
                   "  parameter Real p = Modelica.Math.Vectors.interpolate(tab[:, 1], tab[:, 2], 1.5, 1);\n"
                   "  Real s(start = 0, fixed = true);\nequation\n  der(s) = p;\nend Q;\n")
    fmu = compile_model(src, "Q", backend="embedded", output=tmp_path / "q.fmu", libraries=[MSL]).fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0)
    assert out["s"][-1] == pytest.approx(0.55, rel=1e-9)  # halfway between 0.7 and 0.4
