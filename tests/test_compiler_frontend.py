"""The embedded front end cannot take the tool down, refusals name the model's own file and line,
and a byte-order mark is harmless (issue 14, items 4 and 5)."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import fmpy
import pytest

from trackingbox.cli import main
from trackingbox.compiler import compile_model
from trackingbox.compiler.embedded import FRONTEND_GAPS
from trackingbox.compiler.library import locate, model_files
from trackingbox.compiler.source import resolve_source
from trackingbox.errors import CompileError, UnsupportedConstructError

pytestmark = pytest.mark.compile

DEPTH = 100_000  # parentheses: rumoca recurses once per level


def deep_model(tmp_path: Path) -> Path:
    src = tmp_path / "Deep.mo"
    src.write_text("model Deep\n  Real x;\nequation\n  x = " + "(" * DEPTH + "time" + ")" * DEPTH + ";\nend Deep;\n")
    return src


def test_rumoca_crash_becomes_compile_error(tmp_path, monkeypatch):
    # The worker's rumoca thread gets the usual 8 MiB stack, so the crash comes within seconds.
    monkeypatch.setenv("TRACKINGBOX_FRONTEND_STACK_MB", "8")
    src = deep_model(tmp_path)
    # Independent check that this input really kills a process running rumoca directly.
    probe = subprocess.run(
        [sys.executable, "-c", f"import rumoca; rumoca.Session().load({str(src)!r}, model='Deep')"],
        capture_output=True, timeout=300)
    assert probe.returncode < 0, f"rumoca did not crash on the probe (exit {probe.returncode})"
    with pytest.raises(CompileError) as exc:
        compile_model(src, "Deep", backend="embedded", output=tmp_path / "deep.fmu")
    msg = str(exc.value)
    assert "the Modelica front end crashed on Deep" in msg
    assert "SIG" in msg  # the signal is named
    assert not (tmp_path / "deep.fmu").exists()


def test_cli_prints_one_error_line_on_a_front_end_crash(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("TRACKINGBOX_FRONTEND_STACK_MB", "8")
    src = deep_model(tmp_path)
    code = main(["compile", str(src), "--model", "Deep", "--backend", "embedded", "-o", str(tmp_path / "d.fmu")])
    err = capsys.readouterr().err
    assert code != 0
    assert err.startswith("error: the Modelica front end crashed on Deep")
    assert "Traceback" not in err


def test_recursion_in_translation_is_a_compile_error(tmp_path):
    # 2000 terms: rumoca (64 MiB stack) passes it on as a left-deep tree of 2000 additions,
    # deeper than Python's default recursion limit of 1000 frames.
    terms = " + ".join(f"{k}.0*time" for k in range(2000))
    src = tmp_path / "LongSum.mo"
    src.write_text(f"model LongSum\n  Real x;\nequation\n  x = {terms};\nend LongSum;\n")
    with pytest.raises(CompileError) as exc:
        compile_model(src, "LongSum", backend="embedded", output=tmp_path / "s.fmu")
    assert "LongSum" in str(exc.value) and "too deeply" in str(exc.value)


# A package whose model uses a construct, with a decoy occurrence in another file that sorts
# first: the refusal must name the model's own file and the construct's line there.
PACKAGE = {
    "package.mo": "package P\nend P;\n",
    "package.order": "Decoy\nPlant\n",
    "Decoy.mo": ("within P;\nmodel Decoy\n  Real d(start = 0, fixed = true);\nequation\n"
                 "  der(d) = delay(time, 1);\n  when d > 1 then\n    reinit(d, 0);\n  end when;\nend Decoy;\n"),
    "Plant.mo": ("within P;\nmodel Plant\n  // a comment mentioning when and delay(\n"
                 "  Real x(start = 0, fixed = true);\n  Real y;\nequation\n  der(x) = 1 - x;\n"
                 "  y = delay(x, 0.5);\nend Plant;\n"),
    "Tank.mo": ("within P;\nmodel Tank\n  extends P.Base;\n  Real h(start = 1, fixed = true);\nequation\n"
                "  der(h) = -h;\nend Tank;\n"),
    "Base.mo": ("within P;\npartial model Base\n  Real v(start = 0, fixed = true);\nequation\n"
                "  der(v) = delay(time, 0.5);\nend Base;\n"),
}


@pytest.fixture
def package(tmp_path: Path) -> Path:
    root = tmp_path / "P"
    root.mkdir()
    for name, text in PACKAGE.items():
        (root / name).write_text(text)
    return root


def test_refusal_names_the_models_own_file_and_line(package, tmp_path):
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(package, "P.Plant", backend="embedded", output=tmp_path / "p.fmu")
    msg = str(exc.value)
    assert "delay" in msg
    assert f"{package / 'Plant.mo'}:8" in msg  # y = delay(x, 0.5); is line 8
    assert "Decoy.mo" not in msg


def test_refusal_in_an_extended_class_names_that_class_file(package, tmp_path):
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(package, "P.Tank", backend="embedded", output=tmp_path / "t.fmu")
    msg = str(exc.value)
    assert "delay" in msg
    assert f"{package / 'Base.mo'}:5" in msg
    assert "Decoy.mo" not in msg


def test_model_files_and_locate(package):
    src = resolve_source(package)
    # the model's own file, its base class's, then the enclosing package's (its constants are in scope)
    assert model_files(src, "P.Tank") == (package / "Tank.mo", package / "Base.mo", package / "package.mo")
    assert model_files(src, "P.Plant") == (package / "Plant.mo", package / "package.mo")
    # the comment on line 3 does not count; line 8 holds the call
    assert [(loc.file.name, loc.line) for loc in locate(src, "P.Plant", r"\bdelay\s*\(")] == [("Plant.mo", 8)]


BOM = b"\xef\xbb\xbf"
DECAY = "model Decay\n  Real x(start = 1, fixed = true);\nequation\n  der(x) = -x;\nend Decay;\n"


def x_at_one(fmu: Path) -> float:
    res = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.01, relative_tolerance=1e-8,
                            output=["x"])
    return float(res["x"][-1])


def test_byte_order_mark_in_a_single_file(tmp_path):
    src = tmp_path / "Decay.mo"
    src.write_bytes(BOM + DECAY.encode())
    out = compile_model(src, "Decay", backend="embedded", output=tmp_path / "decay.fmu").fmu
    assert math.isclose(x_at_one(out), math.exp(-1.0), rel_tol=1e-4)  # x(t) = exp(-t)


def test_byte_order_mark_in_a_package_and_refusal_lines_stay_right(tmp_path):
    root = tmp_path / "Q"
    root.mkdir()
    (root / "package.mo").write_bytes(BOM + b"package Q\nend Q;\n")
    (root / "Decay.mo").write_bytes(BOM + b"within Q;\n" + DECAY.encode())
    (root / "Late.mo").write_bytes(BOM + b"within Q;\nmodel Late\n  Real x;\nequation\n  x = delay(time, 1.0);\nend Late;\n")
    out = compile_model(root, "Q.Decay", backend="embedded", output=tmp_path / "q.fmu").fmu
    assert math.isclose(x_at_one(out), math.exp(-1.0), rel_tol=1e-4)
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(root, "Q.Late", backend="embedded", output=tmp_path / "l.fmu")
    assert f"{root / 'Late.mo'}:5" in str(exc.value)


def test_implicit_range_for_is_refused_at_its_line(tmp_path):
    src = tmp_path / "Implicit.mo"
    src.write_text("model Implicit\n  Real x[3];\nequation\n  for i loop\n    x[i] = i;\n  end for;\nend Implicit;\n")
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(src, "Implicit", backend="embedded", output=tmp_path / "i.fmu")
    assert "for-loop without an explicit range" in str(exc.value)
    assert f"{src}:4" in str(exc.value)


def test_if_equation_with_unbalanced_branches_is_refused_at_the_if(tmp_path):
    # invalid Modelica (a non-parameter condition whose branches differ in equation count):
    # rumoca refuses it without a position; the refusal must still point at the if-equation
    src = tmp_path / "Branches.mo"
    src.write_text("model Branches\n  Real x = time;\n  Real y;\nequation\n"
                   "  if x < 0.5 then\n    y = 1;\n  end if;\nend Branches;\n")
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(src, "Branches", backend="embedded", output=tmp_path / "b.fmu")
    assert "if-equation" in str(exc.value)
    assert f"{src}:5" in str(exc.value)
    assert not (tmp_path / "b.fmu").exists()


# Valid constructs that rumoca 0.10.2 refuses with a type or shape error (found on the compliance
# suite): each small model below is valid Modelica, and the refusal must name the construct (in the
# README's words) and the line where it stands, counted by hand in the text.
FRONTEND_GAP_MODELS = {
    "boolean": (
        "model M\n"
        "  Real r[Boolean] = {1, 2};\n"
        "  Real y = r[true];\n"
        "end M;\n",
        "over Boolean", 2),
    "enumeration": (
        "model M\n"
        "  type E = enumeration(a, b);\n"
        "  E r[E];\n"
        "algorithm\n"
        "  for e in E loop\n"
        "    r[e] := e;\n"
        "  end for;\n"
        "end M;\n",
        "enumeration type", 3),
    "string_range": (
        "model M\n"
        "  Real n;\n"
        "algorithm\n"
        "  n := 0;\n"
        '  for s in {"a", "b"} loop\n'
        '    if s == "a" then\n'
        "      n := n + 1;\n"
        "    end if;\n"
        "  end for;\n"
        "end M;\n",
        "array of Strings", 5),
    "ones_integer": (
        "model M\n"
        "  parameter Integer k[2] = ones(2);\n"
        "  Real y = k[1];\n"
        "end M;\n",
        "`ones(...)`", 2),
    "logical_array": (
        "model M\n"
        "  Boolean a[:] = {true, false};\n"
        "  Boolean b[:] = {false, false};\n"
        "  Boolean c[:] = a and b;\n"
        "  Real y = if c[1] then 1 else 0;\n"
        "end M;\n",
        "logical operator", 4),
    "flexible_result": (
        "model M\n"
        "  function twice\n"
        "    input Real u[:];\n"
        "    output Real y[:];\n"
        "  algorithm\n"
        "    y := cat(1, u, u);\n"
        "  end twice;\n"
        "  Real x[:] = twice({1.0, 2.0});\n"
        "end M;\n",
        "flexible array size", 8),
    "cross": (
        "model M\n"
        "  Real c[3] = cross({1, 0, 0}, {0, 1, 0});\n"
        "end M;\n",
        "`cross`/`skew`", 2),
    "end_flexible": (
        "model M\n"
        "  parameter Integer x[2,2] = {{1,1},{1,1}};\n"
        "  parameter Integer y[:,:] = x[1:end-1,1:end-1];\n"
        "  Real z = y[1,1];\n"
        "end M;\n",
        "`end` inside a subscript", 3),
    "concatenation": (
        "model M\n"
        "  Real r[1, 1, 3] = cat(3, {{{1}}}, {{{2, 3}}});\n"
        "end M;\n",
        "`cat(3, ...)`", 2),
    "integer_concatenation": (
        "model M\n"
        "  Integer r[1, 4] = [-1, zeros(1, 2), 1];\n"
        "end M;\n",
        "Integer array concatenated", 2),
    "inherited_inputs": (
        "model M\n"
        "  function F1\n"
        "    input Integer x;\n"
        "  end F1;\n"
        "  function F2\n"
        "    extends F1(x = 10);\n"
        "    output Integer y;\n"
        "  end F2;\n"
        "  function F3\n"
        "    extends F2;\n"
        "  algorithm\n"
        "    y := x;\n"
        "  end F3;\n"
        "  Integer i = F3();\n"
        "end M;\n",
        "through `extends`", 14),
    "partial_application": (
        "model M\n"
        "  partial function F\n"
        "    input Real x;\n"
        "    output Real y;\n"
        "  end F;\n"
        "  function apply\n"
        "    input F f;\n"
        "    input Real x;\n"
        "    output Real y;\n"
        "  algorithm\n"
        "    y := f(x);\n"
        "  end apply;\n"
        "  function scale\n"
        "    input Real k;\n"
        "    input Real x;\n"
        "    output Real y;\n"
        "  algorithm\n"
        "    y := k*x;\n"
        "  end scale;\n"
        "  Real z = apply(function scale(k = 2), time);\n"
        "end M;\n",
        "partial application", 20),
    "partial_derivative": (
        "model M\n"
        "  function g\n"
        "    input Real p;\n"
        "    input Real T;\n"
        "    output Real y;\n"
        "  algorithm\n"
        "    y := p*T;\n"
        "  end g;\n"
        "  function g_T = der(g, T);\n"
        "  function h\n"
        "    input Real p;\n"
        "    input Real T;\n"
        "    output Real y;\n"
        "  algorithm\n"
        "    y := g_T(p, T);\n"
        "  end h;\n"
        "  Real z = h(2, time);\n"
        "end M;\n",
        "partial derivative", 9),
    "flow_outside": (
        "model M\n"
        "  Real y = 1;\n"
        "  flow Real x = 3.0;\n"
        "end M;\n",
        "`flow` prefix", 3),
    "instream_record": (
        "model M\n"
        "  record R\n"
        "    Real x = 2.0;\n"
        "  end R;\n"
        "  connector C\n"
        "    flow Real f;\n"
        "    Real e = 1.0;\n"
        "    stream R r;\n"
        "  end C;\n"
        "  C c;\n"
        "  Real x = inStream(c.r.x);\n"
        "end M;\n",
        "`inStream`", 11),
    "string_of_enum": (
        "model M\n"
        "  type E = enumeration(one, two);\n"
        "  Real y = 1;\n"
        "equation\n"
        '  assert(String(E.one) == "one", "wrong");\n'
        "end M;\n",
        "`String()` of an enumeration", 5),
    "cardinality": (
        "model M\n"
        "  connector C\n"
        "    Real e;\n"
        "    flow Real f;\n"
        "  end C;\n"
        "  model N\n"
        "    C c1;\n"
        "    Real k;\n"
        "  equation\n"
        "    k = cardinality(c1);\n"
        "    c1.e = 1;\n"
        "  end N;\n"
        "  N m;\n"
        "end M;\n",
        "`cardinality()`", 10),
    "function_dimension": (
        "model M\n"
        "  function evenUp\n"
        "    input Real a;\n"
        "    output Integer n;\n"
        "  algorithm\n"
        "    n := integer(ceil(a));\n"
        "    while mod(n, 2) <> 0 loop\n"
        "      n := n + 1;\n"
        "    end while;\n"
        "  end evenUp;\n"
        "  parameter Real a = 2.5;\n"
        "  final parameter Integer ns = evenUp(a);\n"
        "  Real buf[ns](each start = 0, each fixed = true);\n"
        "equation\n"
        "  der(buf) = ones(ns);\n"
        "end M;\n",
        "an array dimension given by an Integer parameter that a function computes", 13),
    "discrete_connection_order": (
        "model M\n"
        "  connector BI = input Boolean;\n"
        "  connector BO = output Boolean;\n"
        "  block Src\n"
        "    parameter Real t0;\n"
        "    BO y;\n"
        "  equation\n"
        "    y = time > t0;\n"
        "  end Src;\n"
        "  block Sw\n"
        "    BI u[2];\n"
        "    output Integer k;\n"
        "  equation\n"
        "    k = if u[1] then 1 elseif u[2] then 2 else 0;\n"
        "  end Sw;\n"
        "  block Trig\n"
        "    BI trigger;\n"
        "    output Integer n(start = 0, fixed = true);\n"
        "  equation\n"
        "    when trigger then\n"
        "      n = pre(n) + 1;\n"
        "    end when;\n"
        "  end Trig;\n"
        "  model Net \"the fan-out in a class the model uses (compiler.discrete_connects reads the model's own)\"\n"
        "    Src p1(t0 = 0.5);\n"
        "    Src p2(t0 = 0.2);\n"
        "    Sw m;\n"
        "    Trig t;\n"
        "  equation\n"
        "    connect(p1.y, t.trigger);\n"
        "    connect(p1.y, m.u[1]);\n"
        "    connect(p2.y, m.u[2]);\n"
        "  end Net;\n"
        "  Net net;\n"
        "end M;\n",
        "connected to several inputs, one of them an element of an input array", 30),
}


@pytest.mark.parametrize("name", sorted(FRONTEND_GAP_MODELS))
def test_front_end_gap_is_refused_naming_the_construct_and_line(tmp_path, name):
    text, construct, line = FRONTEND_GAP_MODELS[name]
    src = tmp_path / "M.mo"
    src.write_text(text)
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(src, "M", backend="embedded", output=tmp_path / "m.fmu")
    msg = str(exc.value)
    assert construct in msg
    assert f"{src}:{line}" in msg
    assert "front end (rumoca" in msg and "does not support" in msg
    assert not (tmp_path / "m.fmu").exists()


def test_every_front_end_gap_is_listed_in_the_readme():
    readme = " ".join((Path(__file__).parents[1] / "README.md").read_text().split())
    missing = [gap.construct for gap in FRONTEND_GAPS if not gap.readme or gap.readme not in readme]
    assert missing == []


def test_invalid_model_without_a_front_end_position_names_the_class_line(tmp_path):
    # a shape error (2 + 3 elements) that is no listed construct: a plain CompileError, and since
    # rumoca gives no position the message names the line declaring the model (line 2, after a comment)
    src = tmp_path / "Bad.mo"
    src.write_text("// adds arrays of different sizes\nmodel Bad\n  Real x[2] = {1, 2};\n"
                   "  Real y[3] = x + {1, 2, 3};\nend Bad;\n")
    with pytest.raises(CompileError) as exc:
        compile_model(src, "Bad", backend="embedded", output=tmp_path / "b.fmu")
    assert not isinstance(exc.value, UnsupportedConstructError)
    assert f"Bad is declared at {src}:2" in str(exc.value)
