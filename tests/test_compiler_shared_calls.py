"""A function called again with the same symbolic arguments is built once (compiler.flat_statements,
``_shared_call``): a call's record result passed to another function, ``sumOf(props(x))``, which the
front end passes field by field (``props(x).a``, ``props(x).b``, ...), and the same call in several
functions used to inline the function's body once per field, and so on down every level of calls (IF97's
property functions in ``Modelica.Fluid.Examples.HeatingSystem``). The values are checked against hand-worked ones, the sharing by counting ``exp`` in each of the translated
model's assignments (one call of ``props`` on the state ``x`` computes one exponential)."""
from __future__ import annotations

import math

import casadi as ca
import fmpy
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.embedded import flatten
from trackingbox.compiler.flatten import FlatTranslator
from trackingbox.compiler.source import resolve_source

pytestmark = pytest.mark.compile

MODEL = """package SC
  record Props
    Real a;
    Real b;
    Real c;
  end Props;
  function props
    input Real x;
    output Props p;
  protected
    Real e;
  algorithm
    assert(x < 10, "props: x out of range");
    e := exp(x);
    p.a := e;
    p.b := e*e;
    p.c := 1/e;
  end props;
  function sumOf "a + b c of a Props"
    input Props p;
    output Real y;
  algorithm
    y := p.a + p.b*p.c;
  end sumOf;
  function twice "2 e: props's record result passed on (the front end reads it field by field)"
    input Real x;
    output Real y;
  algorithm
    y := sumOf(props(x));
  end twice;
  function scaled "a doubled"
    input Props p;
    output Props q;
  algorithm
    q.a := 2*p.a;
    q.b := p.b;
    q.c := p.c;
  end scaled;
  function thrice "3 e: a record result passed on through two levels"
    input Real x;
    output Real y;
  algorithm
    y := sumOf(scaled(props(x)));
  end thrice;
  function four "4 e, from two calls of twice"
    input Real x;
    output Real y;
  algorithm
    y := twice(x) + twice(x);
  end four;
  model M
    Real x(start = 0.5, fixed = true);
    Real y;
    Real z;
    Real w;
  equation
    der(x) = -x;
    y = four(x) + sumOf(props(x));
    z = if x > 0.4 then four(x) else sumOf(props(x));
    w = thrice(x);
  end M;
end SC;
"""


def _exp_counts(model) -> dict[str, int]:
    """The number of exp operations in each assignment of the translated model, by its variable."""
    counts = {}
    for sym, expr in model.assignments:
        f = ca.Function("one", [ca.vertcat(*ca.symvar(expr))], [expr])
        counts[str(sym)] = sum(1 for k in range(f.n_instructions()) if f.instruction_id(k) == ca.OP_EXP)
    return counts


def test_calls_with_the_same_arguments_are_built_once(tmp_path):
    src = tmp_path / "SC.mo"
    src.write_text(MODEL)
    flat = flatten(resolve_source(src), "SC.M")
    model = FlatTranslator(flat, resolve_source(src), "SC.M").translate()
    # y and z each read props(x) 3 * (2 + 1) = 9 times (each sumOf(props(x)) once per field of Props;
    # four(x): two twice(x)); inlined at each read that was 9 exp nodes in each, shared it is one (z's
    # if-expression is no function's if-statement: its two sides are calls on the same x)
    counts = _exp_counts(model)
    assert counts["y"] == 1 and counts["z"] == 1 and counts["w"] <= 1, counts  # (w may read exp(x) from y)
    assert "props: x out of range" in {a.message for a in model.asserts}


def test_shared_calls_keep_their_values(tmp_path):
    src = tmp_path / "SC.mo"
    src.write_text(MODEL)
    fmu = compile_model(src, "SC.M", backend="embedded", output=tmp_path / "sc.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.5, output=["x", "y", "z", "w"])
    for row in out:
        x = 0.5 * math.exp(-row["time"])  # der(x) = -x from 0.5
        e = math.exp(x)
        assert row["x"] == pytest.approx(x, rel=1e-4)
        assert row["y"] == pytest.approx(6 * e, rel=1e-4)
        assert row["w"] == pytest.approx(3 * e, rel=1e-4)  # sumOf(scaled(props(x))): 2 e + e^2/e  # four: 4 e, sumOf(props(x)): e + e^2/e
        if abs(x - 0.4) > 1e-3:  # (at the event itself a row holds the value before it)
            assert row["z"] == pytest.approx(4 * e if x > 0.4 else 2 * e, rel=1e-4)
    assert [row["time"] for row in out if 0.5 * math.exp(-row["time"]) < 0.4], "z's else-branch never taken"
