"""A record variable used whole where the translation has only its fields (issue 35: every
Modelica.Fluid valve sets ``state_a = Medium.setState_phX(...)``) is refused naming the construct and
the line, not reported as an unknown variable; a record passed to a function that the front end
expands into its fields still compiles (closed form)."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

RECORD = """model R
  record S
    Real p;
    Real T;
  end S;
  function mk
    input Real u;
    output S s;
  algorithm
    s := S(p = u, T = 2*u);
  end mk;
  function f
    input S s;
    output Real y;
  algorithm
    y := s.p + s.T;
  end f;
  S s(p = time, T = 2);
  Real y = f(s);
  EXTRA
end R;
"""


def test_a_record_passed_to_a_function_compiles(tmp_path):
    src = tmp_path / "R.mo"
    src.write_text(RECORD.replace("EXTRA", ""))
    res = compile_model(src, "R", backend="embedded", output=tmp_path / "r.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["y"])
    assert np.allclose(out["y"], out["time"] + 2.0)


def test_a_record_set_from_a_function_result_is_refused_at_its_line(tmp_path):
    src = tmp_path / "R.mo"
    src.write_text(RECORD.replace("  S s(p = time, T = 2);", "  S s;").replace("EXTRA", "equation\n  s = mk(time);"))
    with pytest.raises(UnsupportedConstructError, match=r"a record variable used whole \(`s`.* at .*R\.mo:21"):
        compile_model(src, "R", backend="embedded", output=tmp_path / "r.fmu")
