"""An if-statement of a function whose branches reach a while loop evaluates the branch taken only
(compiler.if_switch): the branches are one CasADi switch, not an ``if_else`` of every branch. Values
against the same algorithms in Python and an integral by scipy; the asserts of branches not taken do
not fire (each would fail where its branch is not taken); the loops' functions are reached only through
the switch in the translated model."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import quad

from trackingbox.compiler import compile_model
from trackingbox.compiler.embedded import flatten
from trackingbox.compiler.flatten import FlatTranslator
from trackingbox.compiler.source import resolve_source
from trackingbox.errors import AssertionFailed
from trackingbox.fmu import FMUModel

pytestmark = pytest.mark.compile

MODEL = """package SW
  function newtonSqrt
    input Real a;
    output Real x;
  protected
    Integer i;
  algorithm
    x := max(a, 1);
    i := 0;
    while abs(x*x - a) > 1e-12*a and i < 60 loop
      x := 0.5*(x + a/x);
      i := i + 1;
    end while;
  end newtonSqrt;
  function countUp "k := k + 1 from 0 until k >= n: ceil(n) passes, more than the loop bound above 100"
    input Real n;
    output Real k;
  algorithm
    k := 0;
    while k < n loop
      k := k + 1;
    end while;
  end countUp;
  function pick
    input Real a;
    output Real y;
    output Real z;
  algorithm
    z := 2*a;
    if a > 0 then
      assert(a > 0, "pick: the first branch taken at a <= 0");
      y := newtonSqrt(a);
    elseif a > -1 then
      assert(a <= 0, "pick: the second branch taken at a > 0");
      y := a^2;
      z := -1;
    else
      assert(a <= -1, "pick: the else branch taken at a > -1");
      y := countUp(-37*a) + countUp(37*(a + 3));
    end if;
  end pick;
  model M
    parameter Real top = 10;
    Real a = top - 20*time;
    Real y;
    Real z;
    Real q(start = 0, fixed = true);
  equation
    (y, z) = pick(a);
    der(q) = y;
  end M;
end SW;
"""


def _pick(a: float) -> tuple[float, float]:
    """pick in Python: countUp(n) is ceil(n) for n > 0, else 0."""
    if a > 0:
        return math.sqrt(a), 2 * a
    if a > -1:
        return a * a, -1.0
    return max(0, math.ceil(-37 * a)) + max(0, math.ceil(37 * (a + 3))), 2 * a


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    src = tmp_path_factory.mktemp("ifswitch") / "SW.mo"
    src.write_text(MODEL)
    return src


def test_a_switched_if_statement_keeps_its_values_and_no_other_branch_asserts(source, tmp_path):
    # countUp(37 (a + 3)) takes more than the loop's 100 passes above a = -0.3, countUp(-37 a) below
    # a = -2.7: the else branch's loops would stop the model with "did not end" in the first branch,
    # and each branch's assert fails where its branch is not taken
    fmu = compile_model(source, "SW.M", backend="embedded", output=tmp_path / "sw.fmu").fmu
    stop = 0.59  # a from 10 down to -1.8
    out = FMUModel(fmu).simulate(stop_time=stop, output_interval=0.005, outputs=["a", "y", "z", "q"])
    a, y, z, t = (out[k].to_numpy() for k in ("a", "y", "z", "time"))
    assert np.allclose(a, 10 - 20 * t, atol=1e-12)
    inside = (np.abs(a) > 1e-9) & (np.abs(a + 1) > 1e-9)  # (at a branch's boundary a row may hold either side)
    inside &= np.abs(37 * a - np.round(37 * a)) > 1e-6  # (nor where countUp steps)
    assert (a[inside] > 0).sum() > 40 and ((a[inside] < 0) & (a[inside] > -1)).sum() > 5 and (a[inside] < -1).sum() > 5
    want = np.array([_pick(v) for v in a[inside]])
    assert np.allclose(y[inside], want[:, 0], rtol=1e-12, atol=1e-12)
    assert np.allclose(z[inside], want[:, 1], rtol=0, atol=1e-12)
    # q = integral of y over time: scipy's quadrature of the Python function, split at the branches' ends
    breaks = [t for t in (0.5, 0.55) if t < stop]
    q = sum(quad(lambda t: _pick(10 - 20 * t)[0], lo, hi, limit=200)[0]
            for lo, hi in zip([0.0, *breaks], [*breaks, stop]))
    assert out["q"].to_numpy()[-1] == pytest.approx(q, rel=2e-3)
    # below a = -2.7 the else branch itself runs a loop past its bound: that stops the model, named
    with pytest.raises(AssertionFailed, match=r"did not end within 100 passes"):
        FMUModel(fmu).simulate(stop_time=0.7, output_interval=0.005, outputs=["y"])


def _calls(f: ca.Function) -> list[ca.Function]:
    """The functions *f* calls (nested calls not followed): a switch's are its cases."""
    if f.class_name() == "Switch":
        return list(f.find_functions(1))
    return [f.instruction_MX(k).which_function() for k in range(f.n_instructions())
            if f.instruction_id(k) == ca.OP_CALL]


def _reaches_loop(f: ca.Function, seen: set[str], through_switches: bool) -> bool:
    """Whether *f* calls a folded while loop (compiler.repeat's ``*_repeated*``), itself or further down
    (through CasADi switches too, or not)."""
    for g in _calls(f):
        if g.name() in seen or (g.class_name() == "Switch" and not through_switches):
            continue
        seen.add(g.name())
        if "_repeated" in g.name() or _reaches_loop(g, seen, through_switches):
            return True
    return False


def test_the_loops_of_the_branches_are_reached_only_through_the_switch(source):
    flat = flatten(resolve_source(source), "SW.M")
    model = FlatTranslator(flat, resolve_source(source), "SW.M").translate()
    exprs = [e for _, e in model.assignments]
    f = ca.Function("all", [ca.vertcat(*ca.symvar(ca.vertcat(*exprs)))], exprs)
    assert _reaches_loop(f, set(), through_switches=True), "the translated model runs no while loop"
    assert not _reaches_loop(f, set(), through_switches=False), "a while loop is evaluated outside a switch"
