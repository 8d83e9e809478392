"""``fill`` of an array (``ports.C_outflow = fill(C, nPorts)`` in every ``Modelica.Fluid`` source),
which rumoca 0.10.2 refuses ("expression shape mismatch"), is read as the comprehension it equals
(``compiler.fill_arrays``). Expectations worked by hand from MLS 10.3.3: ``fill(s, n)`` is *n*
copies of *s*, its size followed by the sizes of *s*."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.fill_arrays import fill_arrays_as_comprehensions

MODEL = """model FillArrays
  parameter Integer n = 3;
  Real c[2] = {time, 2*time + 1};
  Real cc[n, 2] = fill(c, n);
  Real x[2, 1];
  Real s[2] = fill(time, 2) "a scalar: as written";
equation
  x = fill(c[2:2],
           2);
end FillArrays;
"""


def test_only_fill_of_an_array_is_rewritten_and_lines_are_kept():
    out, lines = fill_arrays_as_comprehensions(MODEL.encode())
    text = out.decode()
    assert lines == [4, 8]
    assert "cc[n, 2] = {c for tb__k in 1:( n)};" in text
    assert "x = {c[2:2] for tb__k in 1:(\n           2)};" in text
    assert "fill(time, 2)" in text and text.count("\n") == MODEL.count("\n")
    # an element of an array is a scalar: left alone
    assert fill_arrays_as_comprehensions(b"model M\n  Real a[2];\n  Real b[2] = fill(a[1], 2);\nend M;\n")[1] == []


@pytest.mark.compile
def test_fill_of_an_array_compiles_with_its_values(tmp_path):
    src = tmp_path / "FillArrays.mo"
    src.write_text(MODEL)
    res = compile_model(src, "FillArrays", backend="embedded", output=tmp_path / "f.fmu")
    names = [f"cc[{i},{j}]" for i in range(1, 4) for j in (1, 2)] + ["x[1,1]", "x[2,1]", "s[1]"]
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=names)
    t = out["time"]
    for i in range(1, 4):
        assert np.allclose(out[f"cc[{i},1]"], t) and np.allclose(out[f"cc[{i},2]"], 2 * t + 1)
    assert np.allclose(out["x[1,1]"], 2 * t + 1) and np.allclose(out["x[2,1]"], 2 * t + 1)
    assert np.allclose(out["s[1]"], t)
