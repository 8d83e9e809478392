"""Libraries for the embedded compiler (issue 35 item 5, issue 30 item 4): a missing library is
named as such, packages beside the source and on MODELICAPATH are found, --library takes a package
or a directory of packages; external "builtin" functions (Modelica.Math's) are the built-ins."""
from __future__ import annotations

from pathlib import Path

import fmpy
import numpy as np
import pytest

from trackingbox.cli import main
from trackingbox.compiler import compile_model
from trackingbox.errors import CompileError, UnsupportedConstructError

pytestmark = pytest.mark.compile

PLANT = ("model Plant\n  Heat.Capacity c(C = 2);\n  Real y = c.T;\n"
         "  annotation(uses(Heat(version = \"1.0\")));\nend Plant;\n")
HEAT = {
    "package.mo": "package Heat\n  constant Real k = Units.scale;\nend Heat;\n",
    "Capacity.mo": ("within Heat;\nmodel Capacity\n  parameter Real C = 1;\n  Real T(start = 1, fixed = true);\n"
                    "equation\n  C*der(T) = -k*T;\nend Capacity;\n"),
}
UNITS = {"package.mo": "package Units\n  constant Real scale = 4;\nend Units;\n"}


def write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


def final_y(fmu: Path) -> float:
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.5, output=["y"], relative_tolerance=1e-9)
    return float(out["y"][-1])


@pytest.fixture()
def layout(tmp_path) -> dict[str, Path]:
    """A model in its own directory; libraries Heat (which uses Units) and Units side by side elsewhere."""
    model = tmp_path / "work" / "Plant.mo"
    model.parent.mkdir()
    model.write_text(PLANT)
    libs = tmp_path / "libs"
    write(libs / "Heat", HEAT)
    write(libs / "Units", UNITS)
    return {"model": model, "libs": libs}


def test_a_missing_library_is_named_with_what_to_do(layout, tmp_path, capsys):
    with pytest.raises(CompileError) as info:
        compile_model(layout["model"], "Plant", backend="embedded", output=tmp_path / "p.fmu")
    msg = str(info.value)
    assert msg.startswith("`Heat` is used by Plant (at ") and f"{layout['model']}:2)" in msg
    assert "pass --library DIR" in msg and "MODELICAPATH" in msg
    code = main(["compile", str(layout["model"]), "--model", "Plant", "--backend", "embedded",
                 "-o", str(tmp_path / "p.fmu")])
    assert code != 0 and capsys.readouterr().err.startswith("error: `Heat` is used by Plant")
    assert not (tmp_path / "p.fmu").exists()


def test_a_library_beside_a_given_library_is_found(layout, tmp_path):
    # Heat uses Units; only Heat is given: Units is found beside it. k = 4, C = 2: T = exp(-2 t)
    res = compile_model(layout["model"], "Plant", backend="embedded", output=tmp_path / "p.fmu",
                        libraries=[layout["libs"] / "Heat"])
    assert final_y(res.fmu) == pytest.approx(np.exp(-2.0), rel=1e-6)


def test_a_directory_of_libraries_and_modelicapath_are_honoured(layout, tmp_path, monkeypatch):
    res = compile_model(layout["model"], "Plant", backend="embedded", output=tmp_path / "a.fmu",
                        libraries=[layout["libs"]])
    assert final_y(res.fmu) == pytest.approx(np.exp(-2.0), rel=1e-6)
    monkeypatch.setenv("MODELICAPATH", f"{tmp_path / 'nowhere'}:{layout['libs']}")
    res = compile_model(layout["model"], "Plant", backend="embedded", output=tmp_path / "b.fmu")
    assert final_y(res.fmu) == pytest.approx(np.exp(-2.0), rel=1e-6)


def test_a_library_path_that_is_no_package_is_refused(layout, tmp_path):
    with pytest.raises(CompileError, match="library '.*nowhere' does not exist"):
        compile_model(layout["model"], "Plant", backend="embedded", output=tmp_path / "p.fmu",
                      libraries=[tmp_path / "nowhere"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(CompileError, match="is not a Modelica package"):
        compile_model(layout["model"], "Plant", backend="embedded", output=tmp_path / "p.fmu",
                      libraries=[tmp_path / "empty"])


def test_packages_beside_the_source_package_are_found(tmp_path):
    write(tmp_path / "Units", UNITS)
    write(tmp_path / "Heat", HEAT)
    (tmp_path / "Heat" / "Plant.mo").write_text("within Heat;\n" + PLANT.replace("Heat.Capacity", "Capacity"))
    res = compile_model(tmp_path / "Heat", "Heat.Plant", backend="embedded", output=tmp_path / "p.fmu")
    assert final_y(res.fmu) == pytest.approx(np.exp(-2.0), rel=1e-6)


BUILTINS = """
package Fns
  function mySin
    input Real u;
    output Real y;
  external "builtin" y = sin(u);
  end mySin;
  function myAtan2
    input Real u1;
    input Real u2 = 1;
    output Real y;
  external "builtin" y = atan2(u1, u2);
  end myAtan2;
  function myExp
    input Real u;
    output Real y;
  external "builtin" y = exp(u);
  end myExp;
  function nowhere
    input Real u;
    output Real y;
  external "builtin" y = erfc(u);
  end nowhere;
  model Uses
    Real a = mySin(3*time);
    Real b = myAtan2(time - 0.5);
    Real c = myExp(-time);
  end Uses;
  model Unknown
    Real d = nowhere(time);
  end Unknown;
end Fns;
"""


def test_external_builtin_functions_are_the_built_ins(tmp_path):
    src = tmp_path / "Fns.mo"
    src.write_text(BUILTINS)
    res = compile_model(src, "Fns.Uses", backend="embedded", output=tmp_path / "u.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.1, output=["a", "b", "c"])
    t = out["time"]
    assert np.allclose(out["a"], np.sin(3 * t), atol=1e-12)
    assert np.allclose(out["b"], np.arctan2(t - 0.5, 1.0), atol=1e-12)
    assert np.allclose(out["c"], np.exp(-t), atol=1e-12)
    with pytest.raises(UnsupportedConstructError, match=r"external function '(?:Fns\.)?nowhere' at .*Fns.mo:22\."):
        compile_model(src, "Fns.Unknown", backend="embedded", output=tmp_path / "n.fmu")
