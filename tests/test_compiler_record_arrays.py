"""Arrays of records and of components used whole, sliced or through a field (issue 35: Modelica.Fluid's
pipes set their protected ``Medium.ThermodynamicState[nFM+1] statesFM`` by ``statesFM[2:n+1] =
mediums[1:n].state`` and read ``mediums[i].d`` in a comprehension). The flat model holds only each
element's fields (``sFM[1].p``); the translation gives such references their Modelica meaning, one
equation per element and field (MLS 10.6.3). Expected values are worked by hand from the equations."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

SLICED = """model C
  record S
    Real p;
    Real T;
  end S;
  model Vol
    S state;
    parameter Real k = 1;
  equation
    state.p = k*time;
    state.T = 2*k;
  end Vol;
  Vol vols[2](k = {1, 3});
  S[3] sFM "as Modelica.Fluid's pipes' statesFM";
  Real y = sFM[2].p + sFM[3].T;
equation
  sFM[1].p = 0;
  sFM[1].T = 0;
  sFM[2:3] = vols[1:2].state;
end C;
"""

WHOLE = """model D
  record S
    Real p;
    Real T;
  end S;
  model Vol
    S state;
    parameter Real k = 1;
    Real d;
  equation
    state.p = k*time;
    state.T = 2*k;
    d = 10*k;
  end Vol;
  Vol vols[2](k = {1, 3});
  S[2] a;
  S[2] b;
  Real ps[2] = a.p "a field of an array of records";
  Real w[2] = {vols[i].d*time for i in 1:2} "as the pipes' velocities, mediums[i].d";
  Real q[2] = vols.state.T;
equation
  a = vols.state;
  b[2:-1:1] = a;
end D;
"""


def _run(tmp_path, text: str, model: str, names: list[str]):
    src = tmp_path / f"{model}.mo"
    src.write_text(text)
    res = compile_model(src, model, backend="embedded", output=tmp_path / f"{model}.fmu")
    return fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25, output=names)


def test_a_slice_of_an_array_of_records_set_from_a_field_of_components(tmp_path):
    out = _run(tmp_path, SLICED, "C", ["y", "sFM[2].p", "sFM[2].T", "sFM[3].p", "sFM[3].T"])
    t = out["time"]
    # sFM[2] = vols[1].state = (1*t, 2*1), sFM[3] = vols[2].state = (3*t, 2*3)
    assert np.allclose(out["sFM[2].p"], t)
    assert np.allclose(out["sFM[2].T"], 2.0)
    assert np.allclose(out["sFM[3].p"], 3 * t)
    assert np.allclose(out["sFM[3].T"], 6.0)
    assert np.allclose(out["y"], t + 6.0)


def test_arrays_of_records_whole_reversed_and_their_fields(tmp_path):
    out = _run(tmp_path, WHOLE, "D", ["ps[1]", "ps[2]", "w[1]", "w[2]", "q[1]", "q[2]",
                                      "b[1].p", "b[1].T", "b[2].p", "b[2].T"])
    t = out["time"]
    assert np.allclose(out["ps[1]"], t) and np.allclose(out["ps[2]"], 3 * t)  # a = vols.state
    assert np.allclose(out["w[1]"], 10 * t) and np.allclose(out["w[2]"], 30 * t)  # d = 10 k
    assert np.allclose(out["q[1]"], 2.0) and np.allclose(out["q[2]"], 6.0)  # T = 2 k
    # b[2:-1:1] = a: b[1] = a[2], b[2] = a[1]
    assert np.allclose(out["b[1].p"], 3 * t) and np.allclose(out["b[1].T"], 6.0)
    assert np.allclose(out["b[2].p"], t) and np.allclose(out["b[2].T"], 2.0)


def _records(*ps):
    from trackingbox.compiler import arrays as arr
    from trackingbox.compiler.records import Record
    return arr.from_list([Record(p=p, T=2 * p) for p in ps])


def test_equating_arrays_of_records_is_one_residual_per_element_and_field():
    from trackingbox.compiler import records
    res = records.difference(_records(1.0, 2.0), _records(0.5, 2.0), "`a = b`")
    assert res == [0.5, 1.0, 0.0, 0.0]  # (p, T) of element 1, then of element 2


def test_arrays_of_records_of_different_sizes_are_an_error_naming_both_sizes():
    from trackingbox.compiler import records
    with pytest.raises(records.RecordError, match=r"sizes \[2\] and \[3\] equated in `a = b`"):
        records.difference(_records(1.0, 2.0), _records(1.0, 2.0, 3.0), "`a = b`")
    with pytest.raises(records.RecordError, match="array of records and a value that is not one"):
        records.difference(_records(1.0), 1.0, "`a = b`")


def test_a_field_of_an_array_of_records_is_the_array_of_the_fields():
    from trackingbox.compiler import records
    assert list(records.field_of_each(_records(1.0, 4.0), "T", "`a`")) == [2.0, 8.0]
    with pytest.raises(records.RecordError, match="no field 'd'"):
        records.field_of_each(_records(1.0), "d", "`a`")
