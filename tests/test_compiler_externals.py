"""External functions of the MSL on the embedded path, and the front-end rewrites they need.

* LAPACK (``Modelica.Math.Matrices.LAPACK``, :mod:`trackingbox.compiler.lapack`): ``Matrices.solve``
  and ``solve2`` (``dgesv``) against numpy's solve, on a matrix that depends on a tunable
  parameter and a right-hand side that varies with time; ``leastSquares`` and
  ``Polynomials.fitting`` (``dgelsy``) on constants against numpy's least squares and fits worked
  by hand; a singular matrix stops the run with the MSL's message; a least-squares solve on a
  varying matrix and an unmapped routine (``dgeev``) are refused naming the function and its line.
* ``Modelica.Utilities.Streams.error`` (:mod:`trackingbox.compiler.streams_error`) stops the run
  with its message, in an if-equation and in a function.
* A class redeclaration with a literal modification (:mod:`trackingbox.compiler.redeclare_short`)
  keeps it; a function redeclaration with a modification keeps it as rumoca reads it.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler.external_locals import external_locals_as_inputs
from trackingbox.compiler.redeclare_short import short_class_redeclarations
from trackingbox.compiler.streams_error import streams_error_as_assert
from trackingbox.errors import AssertionFailed, UnsupportedConstructError

MATH = MSL / "Math" / "package.mo"

LINEAR = """
model Linear
  parameter Real a = 2;
  parameter Real s = 2;
  Real b[3] = {1 + time, 2, 3*time};
  Real x[3] = Modelica.Math.Matrices.solve([a, 1, 0; 1, 3, 1; 0, 1, 4], b);
  Real X[3, 2] = Modelica.Math.Matrices.solve2([a, 1, 0; 1, 3, 1; 0, 1, 4], [b, 2*b]);
  Real z[2] = Modelica.Math.Matrices.solve([1, 2; 2, 4*s], {1, 1 + time});
  Real xl[2] = Modelica.Math.Matrices.leastSquares([1, 1; 1, 2; 1, 3], {1, 2, 2});
  Real p1[2] = Modelica.Math.Polynomials.fitting({0, 1, 2, 3}, {1, 2, 2, 4}, 1);
  Real p2[3] = Modelica.Math.Polynomials.fitting({0, 1, 2}, {1, 3, 7}, 2);
end Linear;
"""

VARYING_LSQ = """
model VaryingLsq
  Real x[2] = Modelica.Math.Matrices.leastSquares([1, 1; 1, 2; 1, 3 + time], {1, 2, 2});
end VaryingLsq;
"""

EIGEN = """
model Eigen
  Real ev[2, 2] = Modelica.Math.Matrices.eigenValues([1, 2; 3, 4 + time]);
end Eigen;
"""

ERRORS = """
package Errors
  model InEquation
    Real x(start = 1, fixed = true);
  equation
    der(x) = -x;
    if x < 0.5 then
      Modelica.Utilities.Streams.error("level fell below one half");
    end if;
  end InEquation;
  model InFunction
    function check
      input Real v;
      output Real y;
    algorithm
      if v < 0.5 then
        Modelica.Utilities.Streams.error("checked level fell below one half");
      end if;
      y := v;
    end check;
    Real x(start = 1, fixed = true);
    Real y = check(x);
  equation
    der(x) = -x;
  end InFunction;
end Errors;
"""

REDECLARE = """
package Redeclare
  model Base
    parameter Real k = 1;
    Real y = k;
  end Base;
  partial function pf
    input Real u;
    output Real y;
  end pf;
  function lin
    extends pf;
    input Real a = 1;
  algorithm
    y := a*u;
  end lin;
  model Holder
    replaceable model M = Base;
    replaceable function f = lin;
    M m;
    Real z = f(2 + time);
  end Holder;
  model Literal
    parameter Real kk = 4;
    Holder h(redeclare model M = Base(k = 5), redeclare function f = lin(a = 3));
    Holder h2(redeclare function f = lin(a = kk));
  end Literal;
end Redeclare;
"""


def _compile(tmp_path: Path, text: str, model: str, name: str):
    from trackingbox.compiler import compile_model

    src = tmp_path / f"{name}.mo"
    src.write_text(text)
    return compile_model(src, model, backend="embedded", output=tmp_path / f"{name}.fmu", libraries=[MSL])


def _line_of(path: Path, pattern: str) -> int:
    text = path.read_text(encoding="utf-8-sig")
    return text.count("\n", 0, re.search(pattern, text).start()) + 1


def test_fortran_locals_are_read_as_trailing_inputs_keeping_every_line():
    need_msl("Math", "package.mo")
    data = MATH.read_bytes()
    new, lines = external_locals_as_inputs(data)
    assert new.count(b"\n") == data.count(b"\n")
    head = new.index(b"pure function dgesv_vec")
    body = new[head:new.index(b"end dgesv_vec;", head)]
    assert b"protected" not in body
    assert b"input Real Awork[size(A, 1), size(A, 1)]=A;" in body
    assert b"input Integer ipiv[size(A, 1)] = fill(0, size(A, 1));" in body  # a zero for the unbound one
    assert data.count(b"\n", 0, data.index(b"pure function dgesv_vec")) + 1 in lines
    # a C function keeps its protected section
    c_text = b'function f\n  input Real u;\n  output Real y;\nprotected\n  Real w = u;\nexternal "C" y = g(w);\nend f;\n'
    assert external_locals_as_inputs(c_text) == (c_text, [])


@pytest.mark.compile
def test_lapack_solves_match_numpy_and_follow_a_tunable_parameter(tmp_path):
    need_msl("Math", "package.mo")
    from trackingbox.fmu import FMUModel

    res = _compile(tmp_path, LINEAR, "Linear", "Linear")
    names = ([f"x[{i}]" for i in (1, 2, 3)] + [f"X[{i},{j}]" for i in (1, 2, 3) for j in (1, 2)]
             + ["z[1]", "z[2]", "xl[1]", "xl[2]", "p1[1]", "p1[2]", "p2[1]", "p2[2]", "p2[3]"])
    for a in (2.0, 5.0):
        with FMUModel(res.fmu) as model:
            df = model.simulate(stop_time=1.0, output_interval=0.25, outputs=names, parameters={"a": a})
        A = np.array([[a, 1, 0], [1, 3, 1], [0, 1, 4.0]])
        for t, row in zip(df.index if "time" not in df else df["time"], df.itertuples(index=False)):
            b = np.array([1 + t, 2, 3 * t])
            got = dict(zip(df.columns, row))
            assert np.allclose([got[f"x[{i}]"] for i in (1, 2, 3)], np.linalg.solve(A, b), rtol=1e-12, atol=1e-12)
            expect2 = np.linalg.solve(A, np.column_stack([b, 2 * b]))
            assert np.allclose([[got[f"X[{i},{j}]"] for j in (1, 2)] for i in (1, 2, 3)], expect2, rtol=1e-12, atol=1e-12)
            assert np.allclose([got["z[1]"], got["z[2]"]], np.linalg.solve([[1, 2], [2, 8.0]], [1, 1 + t]))
    lsq = np.linalg.lstsq(np.array([[1, 1], [1, 2], [1, 3.0]]), np.array([1, 2, 2.0]), rcond=None)[0]
    assert np.allclose([df["xl[1]"].iloc[0], df["xl[2]"].iloc[0]], lsq, rtol=1e-12)
    # by hand: the line through (0,1),(1,2),(2,2),(3,4): slope 4.5/5, intercept 2.25 - 1.5*0.9
    assert np.allclose([df["p1[1]"].iloc[0], df["p1[2]"].iloc[0]], [0.9, 0.9], rtol=1e-12)
    # three points, degree 2: the parabola through them, u^2 + u + 1
    assert np.allclose([df[f"p2[{i}]"].iloc[0] for i in (1, 2, 3)], [1, 1, 1], rtol=1e-12)
    # s = 1 makes [1, 2; 2, 4 s] singular (det 4 s - 4): Matrices.solve's assert stops the run
    with FMUModel(res.fmu) as model, pytest.raises(AssertionFailed, match="A is singular"):
        model.simulate(stop_time=1.0, output_interval=0.25, outputs=["z[1]"], parameters={"s": 1.0})


@pytest.mark.compile
def test_a_least_squares_solve_on_a_varying_matrix_and_an_unmapped_routine_are_refused(tmp_path):
    need_msl("Math", "package.mo")
    line = _line_of(MATH, r"pure function dgelsy_vec\b")
    with pytest.raises(UnsupportedConstructError,
                       match=rf"external function '(?:Modelica\.Math\.Matrices\.)?LAPACK\.dgelsy_vec' \(LAPACK dgelsy\) "
                             rf"at .*Math/package.mo:{line}: .*depends on parameters or variables"):
        _compile(tmp_path, VARYING_LSQ, "VaryingLsq", "VaryingLsq")
    line = _line_of(MATH, r"pure function dgeev\b")
    with pytest.raises(UnsupportedConstructError,
                       match=rf"external function '(?:Modelica\.Math\.Matrices\.)?LAPACK\.dgeev' "
                             rf"\(external 'FORTRAN 77' routine 'dgeev'\) at .*Math/package.mo:{line}\."):
        _compile(tmp_path, EIGEN, "Eigen", "Eigen")
    assert not (tmp_path / "Eigen.fmu").exists()


@pytest.mark.compile
@pytest.mark.parametrize("model,message", [("InEquation", "level fell below one half"),
                                           ("InFunction", "checked level fell below one half")])
def test_streams_error_stops_the_run_with_its_message(tmp_path, model, message):
    need_msl("Utilities", "Streams.mo")
    from trackingbox.fmu import FMUModel

    res = _compile(tmp_path, ERRORS, f"Errors.{model}", model)
    with FMUModel(res.fmu) as fmu, pytest.raises(AssertionFailed) as exc:
        fmu.simulate(stop_time=2.0, output_interval=0.01, outputs=["x"])
    assert exc.value.message == message
    assert np.log(2) <= exc.value.time <= np.log(2) + 0.01 + 1e-9  # x = exp(-t) reaches 0.5 at ln 2


def test_streams_error_is_read_as_an_assert_in_place():
    need_msl("Blocks", "Continuous.mo")
    data = (MSL / "Blocks" / "Continuous.mo").read_bytes()
    new, lines = streams_error_as_assert(data)
    assert len(new) == len(data) and new.count(b"\n") == data.count(b"\n")
    at = _line_of(MSL / "Blocks" / "Continuous.mo", r"Modelica\.Utilities\.Streams\.error\(\"LimPID")
    assert at in lines
    assert b"assert(not (initType == Init.InitialOutput and (y_start < yMin or y_start > yMax)), " in new
    # error(...) where the function imports Modelica.Utilities.Streams.error
    path = MSL / "Math" / "Nonlinear.mo"
    data = path.read_bytes()
    new, lines = streams_error_as_assert(data)
    assert len(new) == len(data) and new.count(b"\n") == data.count(b"\n")
    assert lines == [_line_of(path, r"(?m)^[ \t]*error\($")]
    assert b"assert(not (fa > 0.0 and fb > 0.0 or fa < 0.0 and fb < 0.0), " in new


@pytest.mark.compile
def test_a_literal_class_redeclaration_and_a_function_redeclaration_keep_their_modifications(tmp_path):
    import fmpy

    from trackingbox.compiler import compile_model

    src = tmp_path / "Redeclare.mo"
    src.write_text(REDECLARE)
    res = compile_model(src, "Redeclare.Literal", backend="embedded", output=tmp_path / "r.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["h.m.y", "h.z", "h2.z"],
                            start_values={"kk": 7.0})
    assert np.allclose(out["h.m.y"], 5.0)  # Base's own k is 1
    assert np.allclose(out["h.z"], 3.0 * (2 + out["time"]))  # lin's own a is 1
    assert np.allclose(out["h2.z"], 7.0 * (2 + out["time"]))  # a function's modification follows the parameter
    data = REDECLARE.encode()
    new, lines = short_class_redeclarations(data)
    assert lines == [REDECLARE.count("\n", 0, REDECLARE.index("redeclare model M = Base(k = 5)")) + 1]
    assert new.count(b"\n") == data.count(b"\n") and b"redeclare function f = lin(a = 3)" in new


MIXED = """
package Mixed
  package Medium
    constant Real cp = 4180;
  end Medium;
  package Medium2
    extends Medium(cp = 1000);
  end Medium2;
  model Holder
    replaceable package M = Medium2 constrainedby Medium;
    Real c = M.cp*(1 + time);
  end Holder;
  model DefaultReplaced "Medium2 is only the default of a package redeclared to Medium"
    Holder h(redeclare package M = Medium);
    Real c1 = Medium.cp*(1 + time);
  end DefaultReplaced;
end Mixed;
"""


def test_a_modified_constant_mixes_in_rumoca_even_from_a_replaced_default_so_it_stays_refused(tmp_path):
    """The check behind "package ... extends ... with a modified constant" (Fluid's
    PartialSimpleMedium on PartialPureSubstance) is still needed: rumoca 0.10.2 gives Medium.cp
    Medium2's 1000 even where Medium2 is only a default that the model redeclares away. Should
    rumoca stop mixing them, the first assertion fails and the refusal can be lifted."""
    import rumoca

    from trackingbox.compiler import compile_model

    flat = rumoca.Session().loads(MIXED, model="Mixed.DefaultReplaced", filename="Mixed.mo").to_dict("flat")
    factor = flat["variables"]["c1"]["binding"]["Binary"]["lhs"]["Literal"]["value"]
    assert factor == {"Integer": 1000}  # Modelica says 4180: Medium itself is not modified
    src = tmp_path / "Mixed.mo"
    src.write_text(MIXED)
    with pytest.raises(UnsupportedConstructError, match=r"package Medium2 extends Medium with a modified constant "
                                                        r"at .*Mixed.mo:7, and Mixed.DefaultReplaced also uses Medium"):
        compile_model(src, "Mixed.DefaultReplaced", backend="embedded", output=tmp_path / "m.fmu")


def test_a_short_class_takes_the_modification_without_its_comments_keeping_every_line():
    text = (b"model A\n  Holder h(x = 1, // first\n    redeclare model M = Base(k = 5, // the gain\n"
            b"      j = 2));\nend A;\n")
    new, lines = short_class_redeclarations(text)
    assert lines == [3] and new.count(b"\n") == text.count(b"\n")
    assert b"model M__tb3_39 = Base(k = 5, j = 2);" in new and b"redeclare model M = M__tb3_39\n" in new
    # a modification that names anything is left to the refusal
    named = text.replace(b"k = 5", b"k = kk")
    assert short_class_redeclarations(named) == (named, [])
