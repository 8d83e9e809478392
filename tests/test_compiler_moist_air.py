"""The package structure of ``Modelica.Media.Air.MoistAir`` on a small library (issue 35, MoistAir
examples): a medium reached through a short package class of the model (``package Medium =
MoistAir``), record constants bound to other packages' record constants and read in its functions
and constants, an import in a function the model never calls (``import Modelica.Math.Polynomials``
in ``MoistAir.dynamicViscosity``), and a package that imports the medium's modified base without
using it (``Modelica.Media.IdealGases.Common.FluidData``). Expectations worked by hand from the
declarations below (MLS 4.4.4, 5.3, 7.2, 13.2)."""
from __future__ import annotations

import re
from pathlib import Path

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model, package_copies
from trackingbox.compiler.library import LibraryIndex
from trackingbox.errors import UnsupportedConstructError

FILES = {
    "package.mo": "package Lib\n  record Data\n    Real MM;\n    Real R_s;\n  end Data;\nend Lib;\n",
    "Poly.mo": ("within Lib;\npackage Poly\n  function eval\n    input Real c[:];\n    input Real u;\n"
                "    output Real y = 0;\n  algorithm\n    for k in 1:size(c, 1) loop\n      y := y*u + c[k];\n"
                "    end for;\n  end eval;\nend Poly;\n"),
    "Consts.mo": ("within Lib;\npackage Consts\n  constant Data Steam(MM = 0.018, R_s = 461.5);\n"
                  "  constant Data Air(MM = 0.029, R_s = 287.0);\nend Consts;\n"),
    "Media/package.mo": (
        "within Lib;\npackage Media\n  partial package Base\n    constant Real k = 1;\n    constant Real c2 = 1;\n"
        "    replaceable partial function f\n      input Real u;\n      output Real y;\n    end f;\n"
        "    replaceable partial function h\n      input Real u;\n      output Real y;\n    end h;\n"
        "    replaceable function g \"inherited as it is: its f is the extending package's\"\n"
        "      input Real u;\n      output Real y;\n    algorithm\n      y := f(u) + 1;\n    end g;\n"
        "  end Base;\n  partial package Condensing\n    extends Base(k = 2);\n  end Condensing;\nend Media;\n"),
    "Media/Moist.mo": (
        "within Lib.Media;\npackage Moist\n  extends Condensing;\n  constant Data steam = Consts.Steam;\n"
        "  constant Data dryair = Consts.Air;\n  constant Real k_mair = steam.MM/dryair.MM;\n"
        "  redeclare function extends f\n  algorithm\n    y := k*(dryair.R_s*u + k_mair);\n  end f;\n"
        "  redeclare function h\n    input Real u;\n    output Real y;\n  algorithm\n    y := c2*u;\n  end h;\n"
        "  function viscosity \"called by no model here\"\n    import Lib.Poly;\n    input Real u;\n"
        "    output Real y;\n  algorithm\n    y := Poly.eval({1, 2}, u);\n  end viscosity;\nend Moist;\n"),
    "Unused.mo": "within Lib;\npackage Unused \"imports Base, uses it nowhere\"\n  import Lib.Media.Base;\n"
                 "  constant Real c = 4;\nend Unused;\n",
    "Used.mo": "within Lib;\npackage Used \"imports Base and reads its constant\"\n  import Lib.Media.Base;\n"
               "  constant Real c = Base.k;\nend Used;\n",
    "Short.mo": ("within Lib;\nmodel Short \"the medium through a short package class\"\n"
                 "  package Medium = Lib.Media.Moist;\n  Real y = Medium.f(time + 1);\n"
                 "  Real r = Medium.k_mair;\nend Short;\n"),
    "Inherited.mo": ("within Lib;\nmodel Inherited \"only a function Moist inherits, through a short class\"\n"
                     "  package Medium = Lib.Media.Moist;\n  Real y = Medium.g(time + 1);\nend Inherited;\n"),
    "Comp.mo": ("within Lib;\nmodel Comp\n  replaceable package Medium = Lib.Media.Base;\n"
                 "  Real y = Medium.g(time + 1);\n  Real w = Medium.h(time + 1);\nend Comp;\n"),
    "Modified.mo": ("within Lib;\nmodel Modified \"as RoomCO2: a modified medium handed to a component\"\n"
                    "  package Medium = Lib.Media.Moist(c2 = 3,\n    k = 2);\n"
                    "  Comp comp(redeclare package Medium = Medium);\n  Real z = Medium.c2;\nend Modified;\n"),
    "OwnElement.mo": ("within Lib;\nmodel OwnElement \"k_mair is Moist's own: no copy\"\n"
                      "  package Medium = Lib.Media.Moist(k_mair = 1);\n  Real y = Medium.h(time);\nend OwnElement;\n"),
    "WithUnused.mo": ("within Lib;\nmodel WithUnused\n  package Medium = Lib.Media.Moist;\n"
                      "  Real y = Medium.f(time + 1);\n  Real c = Unused.c;\nend WithUnused;\n"),
    "WithUsed.mo": ("within Lib;\nmodel WithUsed\n  package Medium = Lib.Media.Moist;\n"
                    "  Real y = Medium.f(time + 1);\n  Real c = Used.c;\nend WithUsed;\n"),
}


@pytest.fixture()
def lib(tmp_path) -> Path:
    root = tmp_path / "Lib"
    for rel, text in FILES.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


def test_front_end_files_take_what_an_unused_function_of_a_taken_file_imports(lib):
    idx = LibraryIndex.build([lib])
    files = {p.relative_to(lib).as_posix() for p in idx.frontend_files("Lib.Short")}
    # Moist.mo is read whole by the front end, which resolves viscosity's import too
    assert {"Media/Moist.mo", "Consts.mo", "Poly.mo"} <= files
    assert not files & {"Unused.mo", "Used.mo"}


def test_a_package_through_a_short_class_is_used_with_its_own_classes(lib):
    idx = LibraryIndex.build([lib])
    # Medium.g is Base.g; the package it is reached through is used too (its f, its constants)
    assert idx.lookup("Medium.g", "Lib.Inherited") == "Lib.Media.Base.g"
    used = idx.used_classes("Lib.Inherited")
    assert "Lib.Inherited.Medium" in used and "Lib.Media.Moist" in used


K_MAIR = 0.018 / 0.029  # steam.MM/dryair.MM, from Consts


@pytest.mark.compile
@pytest.mark.parametrize("model", ["Short", "Inherited", "WithUnused"])
def test_moist_structure_compiles_with_its_values(lib, tmp_path, model):
    res = compile_model(lib, f"Lib.{model}", backend="embedded", output=tmp_path / "m.fmu")
    names = {"Short": ["y", "r"], "Inherited": ["y"], "WithUnused": ["y", "c"]}[model]
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=names)
    # Moist.f: k*(dryair.R_s*u + k_mair), with Moist's k = 2 (Condensing's modification, repeated by Modified), u = time + 1;
    # Base.g adds 1 to it
    f = 2.0 * (287.0 * (out["time"] + 1.0) + K_MAIR)
    assert np.allclose(out["y"], f + 1.0 if model == "Inherited" else f)
    if model == "Short":
        assert np.allclose(out["r"], K_MAIR)
    if model == "WithUnused":
        assert np.allclose(out["c"], 4.0)


@pytest.mark.compile
def test_a_base_read_through_an_import_is_still_refused(lib, tmp_path):
    # Used.c = Base.k is 1 in Modelica, and rumoca 0.10.2 would give it Condensing's 2
    with pytest.raises(UnsupportedConstructError, match=r"extends Base with a modified constant at .*package.mo:22"):
        compile_model(lib, "Lib.WithUsed", backend="embedded", output=tmp_path / "x.fmu")
    assert not (tmp_path / "x.fmu").exists()


def test_a_modified_package_is_given_to_the_front_end_as_a_copy_with_the_modification_in_its_extends(lib):
    idx = LibraryIndex.build([lib])
    (plan,) = package_copies.plans(idx, "Lib.Modified")
    assert (plan.name, plan.package, plan.line) == ("Medium", "Lib.Media.Moist", 3)
    edits = package_copies.patches(idx, "Lib.Modified", lambda f: f.read_bytes())
    model = edits[lib / "Modified.mo"]((lib / "Modified.mo").read_bytes()).decode()
    media = edits[lib / "Media/package.mo"]((lib / "Media/package.mo").read_bytes()).decode()
    assert f"package Medium = Lib.Media.{plan.copy}\n;" in model  # (lines kept)
    assert model.count("\n") == FILES["Modified.mo"].count("\n")
    copy = media[media.index(f"package {plan.copy}"):media.index(f"end {plan.copy};")]
    assert "extends Condensing(c2 = 3,\n    k = 2)" in copy and "redeclare function h" in copy
    assert media.rstrip().endswith("end Media;")
    # an element the package declares itself: left as written
    assert package_copies.plans(idx, "Lib.OwnElement") == []


@pytest.mark.compile
def test_a_modified_package_handed_to_a_component_keeps_its_values(lib, tmp_path):
    res = compile_model(lib, "Lib.Modified", backend="embedded", output=tmp_path / "m.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["comp.y", "comp.w", "z"])
    u = out["time"] + 1.0
    assert np.allclose(out["comp.w"], 3.0 * u)  # Moist.h: c2*u with the modification's c2 = 3
    assert np.allclose(out["comp.y"], 2.0 * (287.0 * u + K_MAIR) + 1.0)  # Base.g: Moist.f + 1
    assert np.allclose(out["z"], 3.0)


FILL = """model FillArray "as a Modelica.Fluid source's ports.C_outflow = fill(C, nPorts)"
  Real c[1] = {time};
  Real s[2] = fill(time, 2) "a scalar: read";
  Real cc[2, 1] = fill(c, 2);
end FillArray;
"""


@pytest.mark.compile
def test_fill_of_an_array_is_refused_naming_itself_and_its_line(tmp_path):
    from trackingbox.compiler.embedded import FILL_OF_ARRAY

    src = tmp_path / "FillArray.mo"
    src.write_text(FILL)
    with pytest.raises(UnsupportedConstructError, match=rf"{re.escape(FILL_OF_ARRAY)} at .*FillArray.mo:4"):
        compile_model(src, "FillArray", backend="embedded", output=tmp_path / "f.fmu")
    assert not (tmp_path / "f.fmu").exists()
    assert FILL_OF_ARRAY in (Path(__file__).parents[1] / "README.md").read_text()
