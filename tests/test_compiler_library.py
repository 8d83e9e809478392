"""The class index and name lookup in a model's scope (issue 35, item "no check looks outside the
model's scope"): Modelica's lookup rules on small packages, the compiler's checks and refusal
locations limited to the classes a model uses, and an unrelated class added beside a model never
changing whether it compiles."""
from __future__ import annotations

from pathlib import Path

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.library import LibraryIndex, scan_file
from trackingbox.compiler.library import locate
from trackingbox.compiler.source import resolve_source, strip_comments
from trackingbox.errors import UnsupportedConstructError


def write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root


LOOKUP = {
    "package.mo": "package L\n  constant Real c = 1;\nend L;\n",
    "Types.mo": "within L;\npackage Types\n  type T = Real(unit = \"K\");\nend Types;\n",
    "Outer.mo": ("within L;\nmodel Outer\n  model Types \"shadows L.Types inside Outer\"\n    Real z;\n  end Types;\n"
                 "  model Inner\n    Types t;\n    L.Types.T u;\n  end Inner;\n  Inner i;\nend Outer;\n"),
    "Base.mo": "within L;\npartial model Base\n  model Part\n    Real p;\n  end Part;\nend Base;\n",
    "Derived.mo": "within L;\nmodel Derived\n  extends Base;\n  Part q \"inherited from Base\";\nend Derived;\n",
    "Imp.mo": ("within L;\nmodel Imp\n  import TT = L.Types.T;\n  import L.Types.*;\n  TT a;\n  T b;\n"
               "end Imp;\n"),
    "Enc.mo": ("within L;\nencapsulated model Enc\n  import L.Types;\n  Types.T x;\n  model Deep\n    Base b;\n"
               "  end Deep;\nend Enc;\n"),
}


@pytest.fixture()
def lookup_index(tmp_path) -> LibraryIndex:
    return LibraryIndex.build([write(tmp_path / "L", LOOKUP)])


def test_lookup_goes_outwards_from_the_scope_and_stops_at_the_first_class(lookup_index):
    idx = lookup_index
    # inside Outer.Inner, Types is Outer.Types (the nearer one), not L.Types
    assert idx.lookup("Types", "L.Outer.Inner") == "L.Outer.Types"
    assert idx.lookup("L.Types.T", "L.Outer.Inner") == "L.Types.T"
    assert idx.lookup("Types", "L.Derived") == "L.Types"
    # an inherited nested class is found through extends
    assert idx.lookup("Part", "L.Derived") == "L.Base.Part"
    # a constant: the longest prefix that is a class
    assert idx.lookup("L.c", "L.Derived") == "L"
    assert idx.lookup("Nowhere.x", "L.Derived") is None


def test_lookup_follows_imports_and_stops_at_encapsulated_classes(lookup_index):
    idx = lookup_index
    assert idx.lookup("TT", "L.Imp") == "L.Types.T"
    assert idx.lookup("T", "L.Imp") == "L.Types.T"
    assert idx.lookup("Types.T", "L.Enc") == "L.Types.T"
    # Enc is encapsulated: L.Base is not visible from inside it by its short name
    assert idx.lookup("Base", "L.Enc.Deep") is None


def test_used_classes_are_what_the_lookup_reaches(lookup_index):
    used = lookup_index.used_classes("L.Outer")
    assert used[0] == "L.Outer"
    assert "L.Outer.Inner" in used and "L.Outer.Types" in used and "L.Types.T" in used
    assert "L.Base" not in used and "L.Imp" not in used


def test_front_end_files_keep_every_class_a_lookup_could_find(lookup_index, tmp_path):
    files = {p.name for p in lookup_index.frontend_files("L.Outer")}
    # Outer's own file, the package, Types.mo (L.Types.T); not the classes nothing names
    assert {"Outer.mo", "package.mo", "Types.mo"} <= files
    assert not files & {"Derived.mo", "Imp.mo", "Enc.mo"}
    # Derived uses Part, found in Base: Base.mo is taken
    assert "Base.mo" in {p.name for p in lookup_index.frontend_files("L.Derived")}


def test_scan_skips_redeclarations_in_modifications_and_partial_applications(tmp_path):
    text = ("package P\n  model M\n    H h(redeclare model R = Q(k = 5));\n    Real y = g(function f(a = 1));\n"
            "  end M;\n  model extends N\n  end N;\n  type E = enumeration(a, b);\nend P;\n")
    file = tmp_path / "P.mo"
    file.write_text(text)
    classes = {c.name: c for c in scan_file(file, strip_comments(text))}
    assert set(classes) == {"P", "P.M", "P.N", "P.E"}
    assert classes["P.N"].class_extends and classes["P.E"].short
    assert (classes["P.M"].line, classes["P.M"].last_line) == (2, 5)


# ------------------------------------------------- an unrelated class never changes a compile
PLANT = {
    "package.mo": "package Lib\nend Lib;\n",
    "Balancing/package.mo": "within Lib;\npackage Balancing\nend Balancing;\n",
    "Balancing/Plant.mo": (
        "within Lib.Balancing;\nmodel Plant \"uses its own P\"\n  package P\n    constant Real k = 2;\n  end P;\n"
        "  Real x(start = 1, fixed = true);\nequation\n  der(x) = -P.k*x;\n"
        "  annotation(Icon(graphics = {Rectangle(extent = {{-100, -100}, {100, 100}})}));\nend Plant;\n"),
}
# beside it, in the same library: a class extends of a package with a modified constant (the compliance
# suite's ClassExtendsClassTypes pattern), and a Rectangle class with a class redeclaration carrying a
# modification (the MSL's MultiBody.Visualizers.Rectangle pattern). Each is refused where it is used.
DECOYS = {
    "Decoys/package.mo": "within Lib;\npackage Decoys\nend Decoys;\n",
    "Decoys/Extended.mo": (
        "within Lib.Decoys;\nmodel Extended\n  model A\n    replaceable package P\n      constant Real k;\n"
        "    end P;\n  end A;\n  extends A;\n  package extends P(k = 1.4)\n    constant Real y = k;\n  end P;\n"
        "  Real z = P.y;\nend Extended;\n"),
    "Rectangle.mo": (
        "within Lib;\nmodel Rectangle\n  model Base\n    parameter Real k = 1;\n  end Base;\n  model Holder\n"
        "    replaceable model M = Base;\n    M m[2];\n  end Holder;\n  parameter Real kk = 5; Holder h(redeclare model M = Base(k = kk));\n"
        "end Rectangle;\n"),
}


def _x_at_one(tmp_path: Path, name: str) -> float:
    fmu = tmp_path / f"{name}.fmu"
    compile_model(tmp_path / "Lib", "Lib.Balancing.Plant", backend="embedded", output=fmu)
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.5, output=["x"], relative_tolerance=1e-9)
    return float(out["x"][-1])


def test_an_unrelated_class_beside_a_model_never_changes_its_compile(tmp_path):
    write(tmp_path / "Lib", PLANT)
    before = _x_at_one(tmp_path, "before")
    write(tmp_path / "Lib", DECOYS)
    after = _x_at_one(tmp_path, "after")
    assert before == pytest.approx(np.exp(-2.0), rel=1e-5)  # der(x) = -2 x from x = 1
    assert after == before
    # the decoys are still refused where they are used
    with pytest.raises(UnsupportedConstructError, match=r"class redeclaration with a modification at .*Rectangle.mo:10"):
        compile_model(tmp_path / "Lib", "Lib.Rectangle", backend="embedded", output=tmp_path / "r.fmu")


def test_locate_searches_only_the_classes_the_model_uses(tmp_path):
    write(tmp_path / "Lib", {
        "package.mo": "package Lib\nend Lib;\n",
        "Util.mo": ("within Lib;\npackage Util\n  function f\n    input Real u;\n    output Real y;\n  algorithm\n"
                    "    y := 2*u;\n  end f;\n  model Unused\n    Real d;\n  equation\n    when time > 1 then\n"
                    "      d = 1;\n    end when;\n  end Unused;\nend Util;\n"),
        "M.mo": "within Lib;\nmodel M\n  Real y = Util.f(time);\nend M;\n",
    })
    source = resolve_source(tmp_path / "Lib")
    assert locate(source, "Lib.M", r"\bwhen\b") == []
    hits = locate(source, "Lib.M", r":=")
    assert [(h.file.name, h.line) for h in hits] == [("Util.mo", 7)]


def test_placing_a_refusal_reads_only_the_files_of_the_used_classes(tmp_path, monkeypatch):
    """A refusal in a model that sits beside a large library file it does not use: the search for
    the construct's line reads the model's own files only, never the large one (on the MSL the
    old whole-file searches took minutes: issue 35)."""
    from trackingbox.compiler import source as source_mod

    big = "".join(f"  model M{k}\n    Real x{k};\n  equation\n    x{k} = {k};\n  end M{k};\n" for k in range(20000))
    write(tmp_path / "Lib", {
        "package.mo": "package Lib\nend Lib;\n",
        "Big.mo": f"within Lib;\npackage Big\n{big}end Big;\n",
        "Plant.mo": ("within Lib;\nmodel Plant\n  Real x(start = 0, fixed = true);\n  Real y;\nequation\n"
                     "  der(x) = 1;\n  y = delay(x, 0.5);\nend Plant;\n"),
    })
    read: list[str] = []
    original = source_mod._code

    def spy(file):
        read.append(Path(file).name)
        return original(file)

    monkeypatch.setattr(source_mod, "_code", spy)
    with pytest.raises(UnsupportedConstructError, match=r"delay.*Plant.mo:7"):
        compile_model(tmp_path / "Lib", "Lib.Plant", backend="embedded", output=tmp_path / "p.fmu")
    assert "Plant.mo" in read and "Big.mo" not in read


# ------------------------------------------------- the library's files are looked at once per compile
def test_one_compile_looks_at_the_library_files_once_and_the_next_sees_a_change(tmp_path, monkeypatch):
    """A compile asks for its library index several times (front end, checks, placing messages);
    the files' sizes and modification times are read on the first request only (on the MSL each
    look is 2500 stats: issue 35). A file changed between two compiles is still seen by the second."""
    from trackingbox.compiler import library

    write(tmp_path / "Lib", PLANT)
    looks: list[Path] = []
    original = library.index_tree

    def spy(root, files=None):
        looks.append(Path(root))
        return original(root, files)

    monkeypatch.setattr(library, "index_tree", spy)
    assert _x_at_one(tmp_path, "first") == pytest.approx(np.exp(-2.0), rel=1e-5)
    assert looks == [tmp_path / "Lib"]
    plant = tmp_path / "Lib" / "Balancing" / "Plant.mo"
    plant.write_text(plant.read_text().replace("constant Real k = 2;", "constant Real k = 3;"))
    looks.clear()
    assert _x_at_one(tmp_path, "second") == pytest.approx(np.exp(-3.0), rel=1e-5)  # der(x) = -3 x from x = 1
    assert looks == [tmp_path / "Lib"]
