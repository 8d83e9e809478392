"""``der(...) = ...`` inside for-loops: compiled right despite rumoca 0.10.2, never silently wrong
(issue 14, "correct or refused, never wrong").

rumoca 0.10.2 flattens ``for i in 1:3 loop der(x[i]) = a[i] - x[i]; end for;`` into
``der(x[3]) = 0.0`` for the third iteration (and later ones). The embedded backend
hands rumoca a rewritten copy (:mod:`trackingbox.compiler.rewrite`) and refuses a flat
model that still carries the bug's signature (:func:`.flatten.check_lost_der_equations`).
The references are the closed-form solutions of the linear ODEs, x(t) = a + (x0 - a) e^(-k t).
"""
from __future__ import annotations

import re
from pathlib import Path

import fmpy
import numpy as np
import pytest
import rumoca

from trackingbox.compiler import compile_model
from trackingbox.compiler.flat_text import check_lost_der_equations
from trackingbox.compiler.flatten import FlatTranslator
from trackingbox.compiler.rewrite import protect_der_equations
from trackingbox.compiler.source import resolve_source
from trackingbox.errors import CompileError, UnsupportedConstructError

pytestmark = pytest.mark.compile

TIMES = np.array([0.0, 0.5, 1.0, 2.0])


def _simulate(tmp_path: Path, text: str, model: str, names: list[str]) -> dict[str, np.ndarray]:
    top = model.split(".")[0]  # the file is named after its top-level class
    src = tmp_path / f"{top}.mo"
    src.write_text(text)
    fmu = compile_model(src, model, backend="embedded", output=tmp_path / f"{top}.fmu").fmu
    res = fmpy.simulate_fmu(str(fmu), stop_time=2.0, output_interval=0.5, relative_tolerance=1e-8,
                            output=names)
    return {n: np.interp(TIMES, res["time"], res[n]) for n in names}


def _first_order(a: float, x0: float, k: float = 1.0) -> np.ndarray:
    """x(t) of dx/dt = k (a - x), x(0) = x0."""
    return a + (x0 - a) * np.exp(-k * TIMES)


# (model text, model name, {variable: (a, x0, k)})
CASES = {
    "1-D, 1:3": ("""
model H
  parameter Real a[3] = {1, 2, 3};
  Real x[3];
equation
  for i in 1:3 loop
    der(x[i]) = a[i] - x[i];
  end for;
end H;
""", "H", {f"x[{i}]": (a, 0.0, 1.0) for i, a in enumerate([1, 2, 3], 1)}),
    "1-D, 1:4, start values": ("""
model H4
  parameter Real a[4] = {1, 2, 3, 4};
  Real x[4](start = {1, 0, 2, -1}, each fixed = true);
equation
  for i in 1:4 loop
    der(x[i]) = a[i] - x[i];
  end for;
end H4;
""", "H4", {f"x[{i}]": (a, x0, 1.0) for i, (a, x0) in enumerate(zip([1, 2, 3, 4], [1, 0, 2, -1]), 1)}),
    "2-D, one loop over two indices": ("""
model H2
  parameter Real k[3, 2] = {{1, 2}, {3, 4}, {5, 6}};
  Real x[3, 2](each start = 1, each fixed = true);
equation
  for i in 1:3, j in 1:2 loop
    der(x[i, j]) = -k[i, j]*x[i, j];
  end for;
end H2;
""", "H2", {f"x[{i},{j}]": (0.0, 1.0, float(2 * (i - 1) + j)) for i in (1, 2, 3) for j in (1, 2)}),
    "nested loops (the inner one loses its third iteration)": ("""
model HN
  parameter Real a[2, 3] = {{1, 2, 3}, {4, 5, 6}};
  Real x[2, 3];
equation
  for i in 1:2 loop
    for j in 1:3 loop
      der(x[i, j]) = a[i, j] - x[i, j];
    end for;
  end for;
end HN;
""", "HN", {f"x[{i},{j}]": (float(3 * (i - 1) + j), 0.0, 1.0) for i in (1, 2) for j in (1, 2, 3)}),
    "loop inside an instantiated component": ("""
package P
  model C
    parameter Real a[3] = {1, 2, 3};
    Real x[3];
  equation
    for i in 1:3 loop
      der(x[i]) = a[i] - x[i];
    end for;
  end C;
  model T
    C c1;
    C c2(a = {4, 5, 6});
  end T;
end P;
""", "P.T", {**{f"c1.x[{i}]": (float(i), 0.0, 1.0) for i in (1, 2, 3)},
             **{f"c2.x[{i}]": (float(i + 3), 0.0, 1.0) for i in (1, 2, 3)}}),
    "no blanks, split over lines, comments, if-equation": ("""
model HS
  parameter Real a[6] = {1, 2, 3, 4, 5, 6};
  parameter Boolean fast = true;
  Real x[6];
equation
  for i in 1:3 loop
der(x[i])=a[i]-x[i]; // no blank before or after
  end for;
  for i in 4:6 loop
    /* der(x[i]) = 0; */
    if fast then
      der(x[i])
        = 2*(a[i] - x[i]);
    else
      der(x[i]) = a[i] - x[i];
    end if;
  end for;
end HS;
""", "HS", {f"x[{i}]": (float(i), 0.0, 1.0 if i <= 3 else 2.0) for i in range(1, 7)}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_der_equations_in_for_loops_simulate_to_the_closed_form(tmp_path, case):
    text, model, expected = CASES[case]
    got = _simulate(tmp_path, text, model, list(expected))
    for name, (a, x0, k) in expected.items():
        assert np.allclose(got[name], _first_order(a, x0, k), rtol=1e-5, atol=1e-6), \
            f"{case}: {name} = {got[name]}, expected {_first_order(a, x0, k)}"


def test_genuine_zero_right_hand_side_in_a_loop_compiles(tmp_path):
    text = """
model Z
  Real x[3](start = {1, 2, 3}, each fixed = true);
  Real y[3](each start = 1, each fixed = true);
equation
  for i in 1:3 loop
    der(x[i]) = 0;
    der(y[i]) = 0.0 - y[i];
  end for;
end Z;
"""
    got = _simulate(tmp_path, text, "Z", ["x[1]", "x[2]", "x[3]", "y[3]"])
    for i in (1, 2, 3):
        assert np.allclose(got[f"x[{i}]"], float(i), atol=1e-9)
    assert np.allclose(got["y[3]"], np.exp(-TIMES), rtol=1e-5, atol=1e-6)


# ---------------------------------------------------------------- the rewrite itself

SOURCE = b"""model R
  Real x[3];
  Real y;
equation
  der(y) = 1; // outside any loop: left alone
  for i in 1:3 loop
    der(x[i]) = -x[i]; /* der(x[i]) = 0; */ "der(z) = 1"
    2*der(x[i]) == 1;
  end for;
algorithm
  for i in 1:3 loop
    der(x[i]) := 1;
  end for;
end R;
"""


def test_rewrite_parenthesises_only_der_equations_in_for_loops():
    rewrite = protect_der_equations(SOURCE)
    lines = rewrite.data.decode().splitlines()
    assert rewrite.lines == (7,)
    assert lines[6] == '   (der(x[i]))= -x[i]; /* der(x[i]) = 0; */ "der(z) = 1"'
    # everything else byte for byte as written, and every offset kept
    assert len(rewrite.data) == len(SOURCE) and rewrite.offsets_kept
    original = SOURCE.decode().splitlines()
    assert [n for n, (a, b) in enumerate(zip(original, lines), 1) if a != b] == [7]


def test_rewrite_without_blanks_keeps_lines_and_later_offsets():
    src = b"equation\n  for i in 1:2 loop\nder(x[i])=-x[i];\n    end for;\n  y = 1;\n"
    rewrite = protect_der_equations(src)
    assert rewrite.data.decode().splitlines()[2] == "(der(x[i]))=-x[i];"
    assert rewrite.data.count(b"\n") == src.count(b"\n")
    # the two inserted parentheses are paid for by blanks of the next line's indentation
    assert rewrite.offsets_kept and rewrite.data.index(b"y = 1") == src.index(b"y = 1")


def test_error_after_a_rewritten_equation_names_the_users_file_and_line(tmp_path):
    src = tmp_path / "E.mo"
    src.write_text("model E\n  Real x[3];\nequation\n  for i in 1:3 loop\n    der(x[i]) = -x[i];\n"
                   "  end for;\n  x[1] = 2 + ;\nend E;\n")
    with pytest.raises(CompileError) as exc:
        compile_model(src, "E", backend="embedded", output=tmp_path / "E.fmu")
    msg = str(exc.value)
    assert f"{src}:7:14" in msg, msg  # the ';' after '+': line and column as the user wrote them
    assert "tbx-frontend" not in msg
    assert not (tmp_path / "E.fmu").exists()



def test_package_with_byte_order_marks_and_loops_compiles_and_refusals_keep_their_line(tmp_path):
    bom = b"\xef\xbb\xbf"
    root = tmp_path / "Q"
    root.mkdir()
    (root / "package.mo").write_bytes(bom + b"package Q\nend Q;\n")
    (root / "Loops.mo").write_bytes(bom + b"within Q;\nmodel Loops\n  parameter Real a[3] = {1, 2, 3};\n"
                                    b"  Real x[3];\nequation\n  for i in 1:3 loop\nder(x[i])=a[i]-x[i];\n"
                                    b"  end for;\nend Loops;\n")
    (root / "Late.mo").write_bytes(bom + b"within Q;\nmodel Late\n  Real x[3];\n  Real y;\nequation\n"
                                   b"  for i in 1:3 loop\nder(x[i])=-x[i];\n  end for;\n  y = delay(x[1], 1.0);\n"
                                   b"end Late;\n")
    fmu = compile_model(root, "Q.Loops", backend="embedded", output=tmp_path / "loops.fmu").fmu
    res = fmpy.simulate_fmu(str(fmu), stop_time=2.0, relative_tolerance=1e-8, output=["x[1]", "x[2]", "x[3]"])
    assert np.allclose([res[f"x[{i}]"][-1] for i in (1, 2, 3)], np.array([1, 2, 3]) * (1 - np.exp(-2.0)),
                       rtol=1e-5)
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(root, "Q.Late", backend="embedded", output=tmp_path / "late.fmu")
    assert f"{root / 'Late.mo'}:9" in str(exc.value)  # the delay(...) line, as the user wrote it


# ---------------------------------------------------------------- the safety net

def _span(start: int, end: int) -> dict:
    return {"source": 7, "start": start, "end": end}


def _ref(name: str, index: int) -> dict:
    return {"VarRef": {"name": {"name": name, "component_ref": {"parts": []}},
                       "subscripts": [{"Index": {"value": index, "span": _span(0, 1)}}],
                       "span": _span(0, 1)}}


def _der_equation(index: int, literal_span: dict, equation_span: dict) -> dict:
    return {"residual": {"Binary": {"op": "Sub",
                                    "lhs": {"BuiltinCall": {"function": "Der", "args": [_ref("x", index)],
                                                            "span": _span(40, 49)}},
                                    "rhs": {"Literal": {"value": {"Real": 0.0}, "span": literal_span}},
                                    "span": equation_span}},
            "span": equation_span, "origin": {"ComponentEquation": {"component": ""}}}


LOOP_TEXT = "model L\n  Real x[3];\nequation\n  for i in 1:3 loop\n    der(x[i]) = 0;\n  end for;\nend L;\n"
ITERATOR = LOOP_TEXT.index("for i") + 4  # offset of the iterator i
ZERO = LOOP_TEXT.index("= 0;") + 2  # offset of the literal 0


def test_check_refuses_a_literal_the_front_end_made_up(tmp_path):
    src = tmp_path / "L.mo"
    src.write_text(LOOP_TEXT)
    loop = _span(ITERATOR, ITERATOR + 1)
    flat = {"equations": [_der_equation(1, _span(ZERO, ZERO + 1), loop),
                          _der_equation(3, loop, loop)]}
    with pytest.raises(CompileError) as exc:
        check_lost_der_equations(flat, resolve_source(src), "L")
    msg = str(exc.value)
    assert "lost the right-hand side of 1 equation(s) of L" in msg
    assert "der(x[3])" in msg and "der(x[1])" not in msg
    assert f"{src}:4" in msg  # the line of the for-loop


def test_check_passes_a_zero_the_user_wrote(tmp_path):
    src = tmp_path / "L.mo"
    src.write_text(LOOP_TEXT)
    # the literal carries its own text's span (not the equation's) ...
    loop = _span(ITERATOR, ITERATOR + 1)
    flat = {"equations": [_der_equation(i, _span(ZERO, ZERO + 1), loop) for i in (1, 2, 3)]}
    check_lost_der_equations(flat, resolve_source(src), "L")
    # ... and even one whose span were the equation's own passes when the text there is that literal
    zero = _span(ZERO, ZERO + 1)
    check_lost_der_equations({"equations": [_der_equation(1, zero, zero)]}, resolve_source(src), "L")


def _raw_flat(tmp_path: Path, text: str, model: str) -> tuple[dict, Path]:
    """rumoca's flat model of *text* as written (without the embedded backend's rewrite)."""
    src = tmp_path / f"{model}.mo"
    src.write_text(text)
    return rumoca.Session().load(str(src), model=model).to_dict("flat"), src


def test_translator_refuses_rumocas_own_lost_equation(tmp_path):
    flat, src = _raw_flat(tmp_path, CASES["1-D, 1:3"][0], "H")
    rhs = [eq["residual"]["Binary"]["rhs"] for eq in flat["equations"]]
    if "Literal" not in rhs[2]:
        pytest.skip("rumoca no longer loses der(x[3]) = a[3] - x[3] (bug fixed upstream): nothing to detect")
    with pytest.raises(CompileError) as exc:
        FlatTranslator(flat, resolve_source(src), "H").translate()
    msg = str(exc.value)
    assert re.search(r"der\(x\[3\]\) = \.\.\. came back as der\(x\[3\]\) = 0\.0 \(for-loop at .*H\.mo:6\)", msg), msg  # line 6: "for i in 1:3 loop"
    assert "der(x[1])" not in msg and "der(x[2])" not in msg


def test_translator_passes_rumocas_parenthesised_form(tmp_path):
    import casadi as ca

    text = CASES["1-D, 1:3"][0].replace("der(x[i]) =", "(der(x[i])) =")
    flat, src = _raw_flat(tmp_path, text, "H")
    model = FlatTranslator(flat, resolve_source(src), "H").translate()
    # and translates it to the model's own equations: der(x[i]) = a[i] - x[i] for every i (the third
    # one too), evaluated from the causalised assignments at x = (0.5, 0.25, 4) with a = (1, 2, 3)
    assert [s.name for s in model.states] == ["x[1]", "x[2]", "x[3]"]
    assert [(p.name, p.value) for p in model.parameters] == [("a[1]", 1.0), ("a[2]", 2.0), ("a[3]", 3.0)]
    symbols, values = [], []
    for symbol, expr in model.assignments:  # in evaluation order: substitute the earlier ones
        values.append(ca.substitute([expr], symbols, values)[0] if symbols else expr)
        symbols.append(symbol)
    ders = [next(v for s, v in zip(symbols, values) if ca.is_equal(s, model.derivative[st.name]))
            for st in model.states]
    f = ca.Function("f", [ca.vertcat(*[st.sym for st in model.states]),
                          ca.vertcat(*[p.sym for p in model.parameters])], [ca.vertcat(*ders)])
    x = np.array([0.5, 0.25, 4.0])
    assert np.asarray(f(x, [1.0, 2.0, 3.0])).ravel().tolist() == pytest.approx([0.5, 1.75, -1.0], abs=1e-15)
