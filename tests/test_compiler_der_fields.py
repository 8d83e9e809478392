"""``der`` of a field of an array of components (``der(mediums.h) = zeros(n)`` in
``Modelica.Fluid.Interfaces.PartialDistributedVolume``), which rumoca 0.10.2 refuses, is read element
by element (``compiler.der_fields``). Expectations worked by hand: ``der(m.h) = {1, 2}`` from
``m.h = {0, 0}`` gives ``m[i].h = i*t``; the steady start ``der(m.h) = zeros(2)`` of
``der(m[i].h) = -m[i].h + i`` gives ``m[i].h = i`` for all time."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.der_fields import component_array_der

LIB = """package D
  model M
    Real h;
  end M;
  model Ramp
    M m[2];
  equation
    der(m.h) = {1, 2};
  initial equation
    m.h = {0, 0};
  end Ramp;
  model Steady
    parameter Integer n = 2;
    M[n] m;
  equation
    der(m[1].h) = -m[1].h + 1;
    der(m[2].h) = -m[2].h + 2;
  initial equation
    der(m.h) = zeros(n);
  end Steady;
end D;
"""


@pytest.mark.compile
@pytest.mark.parametrize("model, expected", [
    ("Ramp", lambda t: (t, 2 * t)),
    ("Steady", lambda t: (np.ones_like(t), 2 * np.ones_like(t))),
])
def test_der_of_a_field_of_a_component_array_is_the_array_of_derivatives(tmp_path, model, expected):
    src = tmp_path / "D.mo"
    src.write_text(LIB)
    res = compile_model(src, f"D.{model}", backend="embedded", output=tmp_path / f"{model}.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25, output=["m[1].h", "m[2].h"])
    one, two = expected(out["time"])
    assert np.allclose(out["m[1].h"], one, atol=1e-6)
    assert np.allclose(out["m[2].h"], two, atol=1e-6)


def test_only_one_dimensional_component_arrays_declared_in_the_file_are_rewritten():
    text = (b"model X\n  N n;\n  M[2, 2] q;\n  M r[3];\nequation\n  der(n.h) = {1, 2};\n  der(q.h) = zeros(2, 2);\n"
            b"  der(r.h) = zeros(3); // der(r.h)\n  der(s.h) = 0;\nend X;\n")
    out, lines = component_array_der(text)
    assert lines == [8]
    assert out.splitlines()[7] == b"  {der(r[k__tb].h) for k__tb in 1:size(r, 1)} = zeros(3); // der(r.h)"
    assert out.count(b"\n") == text.count(b"\n")


LOOP = """package L
  model M
    Real h;
    Real X[2];
  end M;
  model Loop "SteadyStateInitial of PartialDistributedVolume's substances"
    parameter Integer n = 2;
    M m[n];
  equation
    der(m[1].h) = -m[1].h + 1;
    der(m[2].h) = -m[2].h + 2;
    der(m[1].X) = {1, 2} - m[1].X;
    der(m[2].X) = {2, 4} - m[2].X;
  initial equation
    for i in 1:n loop
      der(m[i].h) = 0;
    end for;
    for i in 1:n loop
      der(m[i].X) =
        zeros(2);
    end for;
  end Loop;
end L;
"""


@pytest.mark.compile
def test_a_for_equation_of_der_of_a_component_array_element_is_the_array_equation(tmp_path):
    src = tmp_path / "L.mo"
    src.write_text(LOOP)
    res = compile_model(src, "L.Loop", backend="embedded", output=tmp_path / "loop.fmu")
    names = ["m[1].h", "m[2].h", "m[1].X[1]", "m[1].X[2]", "m[2].X[1]", "m[2].X[2]"]
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25, output=names)
    # steady from the start: h_i = i, X_i = {i, 2 i}
    for name, value in zip(names, [1, 2, 1, 2, 2, 4]):
        assert np.allclose(out[name], value, atol=1e-6), name


def test_a_for_equation_is_rewritten_on_its_own_lines():
    out, lines = component_array_der(LOOP.encode())
    assert out.count(b"\n") == LOOP.count("\n")
    text = out.decode().splitlines()
    assert text[14].strip() == "{der(m[i].h) for i in 1:n} = zeros(n);"
    assert text[17].strip() == "{der(m[i].X) for i in 1:n} = zeros(n, 2);"
    assert lines == [15, 18]
    equation = LOOP.replace("  initial equation\n", "").encode()  # the same loops in an equation section
    assert component_array_der(equation) == (equation, [])
