"""The adjoint derivative left out of the embedded path's C (trackingbox.compiler.c_prune).

Expectations are worked by hand: which generated functions a small hand-written call graph keeps,
and the directional derivative of ``der(x) = -k*x^2 + f(x)`` with respect to ``x`` at its start.
"""
from __future__ import annotations

import re
import shutil
import zipfile
from pathlib import Path

import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.c_prune import drop_adjoint

SIGNATURE = "(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem)"


def _function(n: int, name: str, calls: list[int]) -> str:
    body = "".join(f"  if (casadi_f{c}(arg, res, iw, w, 0)) return 1;\n" for c in calls)
    return f"/* {name}:(i0)->(o0) */\nstatic int casadi_f{n}{SIGNATURE} {{\n{body}  return 0;\n}}\n\n"


def _entry(name: str, n: int) -> str:
    return (f"CASADI_SYMBOL_EXPORT int {name}{SIGNATURE.replace(') ', ')')}{{\n"
            f"  return casadi_f{n}(arg, res, iw, w, mem);\n}}\n\n")


def test_only_what_the_model_and_its_forward_derivative_call_is_kept() -> None:
    # f0 = model -> f4; f1 = fwd1 -> f4, f5; f2 = adj1 -> f3, f5; f3 -> f6; f7 called by nothing
    text = ("#define casadi_f2 CASADI_PREFIX(f2)\n#define casadi_f3 CASADI_PREFIX(f3)\n"
            + _function(4, "g", []) + _function(5, "fwd1_g", []) + _function(6, "adj1_h", [])
            + _function(3, "adj1_g", [6]) + _function(7, "unused", [])
            + _function(0, "m", [4]) + _entry("m", 0)
            + _function(1, "fwd1_m", [4, 5]) + _entry("fwd1_m", 1)
            + _function(2, "adj1_m", [3, 5]) + _entry("adj1_m", 2))
    new, found = drop_adjoint(text, "m")
    assert found
    defined = set(re.findall(r"static int (casadi_f\d+)\(", new))
    assert defined == {"casadi_f0", "casadi_f1", "casadi_f4", "casadi_f5"}
    assert "/* adj1_g:" not in new and "/* unused:" not in new  # their comment lines go with them
    entry = new[new.index("int adj1_m("):]
    assert "return 1;" in entry.split("}\n", 1)[0]
    # nothing to drop in C without the adjoint entry (another model's name)
    assert drop_adjoint(text, "other") == (text, False)


MODEL = """
model Sq
  function f
    input Real u;
    output Real y;
  algorithm
    y := u*u*u;
  end f;
  parameter Real k = 0.5;
  Real x(start = 2, fixed = true);
equation
  der(x) = -k*x^2 + f(x);
end Sq;
"""


@pytest.mark.compile
def test_the_fmu_keeps_its_directional_derivative_and_refuses_the_adjoint(tmp_path: Path) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("no C compiler (gcc) on PATH: the embedded path cannot build an FMU")
    from fmpy import read_model_description
    from fmpy.fmi3 import FMU3Model

    src = tmp_path / "Sq.mo"
    src.write_text(MODEL)
    fmu = compile_model(src, "Sq", backend="embedded", output=tmp_path / "Sq.fmu").fmu
    md = read_model_description(str(fmu))
    with zipfile.ZipFile(fmu) as zf:
        xml = zf.read("modelDescription.xml").decode()
        sources = [zf.read(n).decode() for n in zf.namelist() if n.endswith(".c")]
    assert 'providesAdjointDerivatives="false"' in xml
    assert 'providesDirectionalDerivatives="true"' in xml
    assert not any("/* adj1_Sq:" in s for s in sources)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    der_x = next(v.valueReference for v in md.modelVariables if v.name == "der(x)")
    unzipped = tmp_path / "unzipped"
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(unzipped)
    model = FMU3Model(guid=md.guid, unzipDirectory=str(unzipped), modelIdentifier=md.modelExchange.modelIdentifier,
                      instanceName="sq")
    model.instantiate()
    try:
        model.enterInitializationMode()
        model.exitInitializationMode()
        model.enterContinuousTimeMode()
        # by hand at x = 2, k = 0.5: der(x) = -2 + 8 = 6; d der(x)/dx = -2*k*x + 3*x^2 = -2 + 12 = 10
        assert model.getFloat64([der_x])[0] == pytest.approx(6.0, rel=1e-12)
        assert model.getDirectionalDerivative([der_x], [vr["x"]], [1.0])[0] == pytest.approx(10.0, rel=1e-12)
        with pytest.raises(Exception, match="fmi3GetAdjointDerivative"):
            model.getAdjointDerivative([der_x], [vr["x"]], [1.0])
    finally:
        model.terminate()
        model.freeInstance()
