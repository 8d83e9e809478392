"""Function calls whose arguments are all numbers are evaluated once per definition and arguments
(compiler.flat_statements): every use keeps its value (hand-worked), and an assert such a call
records still stops the model where its condition fails."""
from __future__ import annotations

import math

import fmpy
import pytest

from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

MODEL = """package NC
  function root "Newton's square root"
    input Real a;
    output Real x;
  protected
    Integer i;
  algorithm
    x := max(a, 1);
    i := 0;
    while abs(x*x - a) > 1e-12*a and i < 60 loop
      x := 0.5*(x + a/x);
      i := i + 1;
    end while;
  end root;
  function half
    input Real a;
    output Real y;
  algorithm
    assert(a > 0, "half needs a positive argument");
    y := a/2;
  end half;
  model Vessel
    parameter Real p = 2;
    parameter Real r[3] = {root(p), root(p), root(p) + half(4)};
    Real x(start = root(p), fixed = true);
  equation
    der(x) = -x + root(9);
  end Vessel;
  model M
    Vessel a;
    Vessel b(p = 2);
    Vessel c(p = 5);
    Real y = half(2) + half(2) + a.r[3];
  end M;
end NC;
"""


def test_numeric_calls_evaluated_once_keep_every_value(tmp_path):
    src = tmp_path / "NC.mo"
    src.write_text(MODEL)
    fmu = compile_model(src, "NC.M", backend="embedded", output=tmp_path / "nc.fmu").fmu
    names = ["a.r[1]", "a.r[3]", "b.r[2]", "c.r[3]", "y", "a.x", "c.x"]
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.5, output=names)
    first, last = out[0], out[-1]
    assert first["a.r[1]"] == pytest.approx(math.sqrt(2), rel=1e-12)
    assert first["a.r[3]"] == pytest.approx(math.sqrt(2) + 2, rel=1e-12)
    assert first["b.r[2]"] == pytest.approx(math.sqrt(2), rel=1e-12)
    assert first["c.r[3]"] == pytest.approx(math.sqrt(5) + 2, rel=1e-12)
    assert first["y"] == pytest.approx(2 + math.sqrt(2) + 2, rel=1e-12)
    assert first["a.x"] == pytest.approx(math.sqrt(2), rel=1e-9)
    assert first["c.x"] == pytest.approx(math.sqrt(5), rel=1e-9)
    # x' = 3 - x from x0: x(1) = 3 + (x0 - 3) e^-1
    assert last["c.x"] == pytest.approx(3 + (math.sqrt(5) - 3) * math.exp(-1), rel=1e-4)


def test_an_assert_of_a_numeric_call_still_stops_the_model(tmp_path, capfd):
    src = tmp_path / "NC.mo"
    src.write_text(MODEL.replace("Real y = half(2) + half(2) + a.r[3];",
                                 "Real y = half(2) + half(-2) + half(2) + half(-2);"))
    fmu = compile_model(src, "NC.M", backend="embedded", output=tmp_path / "nc.fmu").fmu
    with pytest.raises(Exception, match="fmi3ExitInitializationMode failed"):
        fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.5)
    assert "half needs a positive argument" in capfd.readouterr().out
