"""Boolean and Integer networks: fan-outs to elements of input arrays, and ``pre(u)`` at initialisation.

* rumoca 0.10.2 could not orient a discrete connection set where an output feeds a scalar input
  and an element of an input array ("element assignments must cover a discrete coordinate exactly
  once"); :mod:`trackingbox.compiler.discrete_connects` gives it those connections as the
  equations they mean.
* ``initial equation pre(u) = pre_u_start`` (the MSL's edge blocks) gives ``pre(u)`` at
  initialisation, not ``u`` (:mod:`trackingbox.compiler.initial_pre`); read as ``u`` it made a
  when-clause on ``change(u)`` fire after initialisation for a change that never happened.

Checked against truth tables and counts worked by hand from the blocks' definitions in the MSL.
"""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model
from trackingbox.compiler.discrete_connects import equations_for
from trackingbox.compiler.library import index_for
from trackingbox.compiler.source import resolve_source

pytestmark = pytest.mark.compile

NET = """
package Net
  connector BooleanInput = input Boolean;
  connector BooleanOutput = output Boolean;
  connector RealInput = input Real;
  connector RealOutput = output Real;
  block Src
    parameter Real t0 = 0.5;
    BooleanOutput y;
  equation
    y = time > t0;
  end Src;
  block Not
    BooleanInput u;
    BooleanOutput y;
  equation
    y = not u;
  end Not;
  block And
    parameter Integer nu = 2;
    BooleanInput u[nu];
    BooleanOutput y;
  equation
    y = u[1] and u[2];
  end And;
  block RSrc
    RealOutput y = time;
  end RSrc;
  block RSum
    RealInput u[2];
    RealOutput y = u[1] + u[2];
  end RSum;
  block RGain
    RealInput u;
    RealOutput y = 3*u;
  end RGain;
  model M "p feeds t.u and m.u[1]; q feeds m.u[2]: t.y = not p.y, m.y = p.y and q.y"
    Src p(t0 = 0.5);
    Not t;
    And m;
    Src q(t0 = 0.25);
    RSrc r;
    RGain g;
    RSum s;
  equation
    connect(p.y, t.u);
    connect(p.y, m.u[1]);
    connect(q.y, m.u[2]);
    connect(r.y, g.u);
    connect(r.y, s.u[1]);
    connect(r.y, s.u[2]);
  end M;
  model Counts "a when-clause on change(u) with pre(u) given at initialisation"
    Boolean u = time < 0.5;
    Boolean c;
    Integer n(start = 0, fixed = true);
    Integer y;
  initial equation
    pre(u) = false;
    pre(y) = 5;
  equation
    c = change(u);
    when c then
      n = pre(n) + 1;
    end when;
    y = if time > 0.3 then 1 else pre(y);
  end Counts;
end Net;
"""


@pytest.fixture(scope="module")
def net(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("net")
    src = d / "Net.mo"
    src.write_text(NET)
    return src


def test_only_discrete_fan_outs_to_array_elements_are_read_as_equations(net):
    index = index_for(resolve_source(net))
    # the Real fan-out (r.y) is left as written: rumoca orients continuous sets itself
    assert equations_for(index, "Net.M") == {("p.y", "m.u[1]"): "m.u[1] = p.y"}
    assert equations_for(index, "Net.Counts") == {}


def test_a_discrete_output_feeding_an_input_and_an_array_element(net, tmp_path):
    fmu = compile_model(net, "Net.M", backend="embedded", output=tmp_path / "m.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.01,
                            output=["t.y", "m.y", "m.u[1]", "g.y", "s.y"])
    t = out["time"]
    away = (np.abs(t - 0.5) > 1e-6) & (np.abs(t - 0.25) > 1e-6)
    p, q = t > 0.5, t > 0.25
    assert np.array_equal(out["t.y"][away].astype(bool), ~p[away])
    assert np.array_equal(out["m.u[1]"][away].astype(bool), p[away])
    assert np.array_equal(out["m.y"][away].astype(bool), (p & q)[away])
    assert np.max(np.abs(out["g.y"] - 3 * t)) < 1e-12 and np.max(np.abs(out["s.y"] - 2 * t)) < 1e-12


def test_pre_given_at_initialisation_is_not_the_variable_itself(net, tmp_path):
    """u = time < 0.5 with pre(u) = false: change(u) is true at initialisation only, where a
    when-clause never fires; n counts the one change at t = 0.5. y = pre(y) = 5 until t = 0.3."""
    fmu = compile_model(net, "Net.Counts", backend="embedded", output=tmp_path / "c.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.01, output=["n", "y"])
    t = out["time"]
    away = (np.abs(t - 0.5) > 1e-6) & (np.abs(t - 0.3) > 1e-6)
    assert np.array_equal(out["n"][away], np.where(t > 0.5, 1, 0)[away])
    assert np.array_equal(out["y"][away], np.where(t > 0.3, 1, 5)[away])


def _simulate(model: str, names: list[str], tmp_path):
    need_msl()
    fmu = compile_model(MSL, model, backend="embedded", output=tmp_path / "x.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=10.0, output_interval=0.01, output=names)
    assert out["time"][-1] == pytest.approx(10.0)
    return out


def _away(t: np.ndarray, events) -> np.ndarray:
    return np.min(np.abs(t[:, None] - np.asarray(events, dtype=float)[None, :]), axis=1) > 1e-3


def test_msl_boolean_network1_follows_its_truth_tables(tmp_path):
    """booleanPulse1 (20 % of 1 s), booleanPulse2 (80 % of 1 s), booleanStep (1.5 s) through
    And, Or, Xor, Nand, Nor, Not; onDelay (1 s) of booleanTable {2, 4, 6, 6.5, 7, 9, 11};
    set1 false at each rising, true at each falling edge of pulse2; triggeredAdd adds 2 at each
    change of pulse2 after the start (0.8, 1, 1.8, 2, ... s)."""
    names = ["and1.y", "or1.y", "xor1.y", "nand1.y", "or2.y", "nor1.y", "onDelay.y", "set1.y", "triggeredAdd.y"]
    out = _simulate("Modelica.Blocks.Examples.BooleanNetwork1", names, tmp_path)
    t = out["time"]
    p1, p2, step = (t % 1) < 0.2, (t % 1) < 0.8, t >= 1.5
    and1 = p1 & step & p2
    or1 = and1 | p2
    xor1 = or1 ^ p2
    nand1 = ~(xor1 & p2)
    or2 = ~(nand1 | p2)
    on = ((t >= 3) & (t < 4)) | ((t >= 8) & (t < 9))
    changes = np.sort(np.concatenate([np.arange(0.8, 10.5, 1.0), np.arange(1.0, 10.5, 1.0)]))
    count = np.searchsorted(changes, t + 1e-9)
    ok = _away(t, [*np.arange(0, 11, 1.0), *np.arange(0.2, 11, 1.0), *np.arange(0.8, 11, 1.0), 1.5, 3, 4, 8, 9])
    expected = {"and1.y": and1, "or1.y": or1, "xor1.y": xor1, "nand1.y": nand1, "or2.y": or2, "nor1.y": ~or2,
                "onDelay.y": on, "set1.y": ~p2, "triggeredAdd.y": 2 * count}
    for name, want in expected.items():
        assert np.array_equal(out[name][ok].astype(float), want[ok].astype(float)), name
    assert out["triggeredAdd.y"][0] == 0  # no change at the start: pre(u) = false is pre(u)'s, not u's


def test_msl_integer_network1_adds_multiplies_counts_and_switches(tmp_path):
    """realToInteger rounds 3 sin(0.2 pi t) to the nearest integer; sum adds integerStep (3 from
    2 s) and 1; product multiplies sum and integerStep; triggeredAdd counts booleanPulse1's rising
    edges after the start (1 per second); multiSwitch1 gives 4 while booleanPulse1 (50 % of 1 s),
    else 6 while booleanPulse2 (80 % of 2 s), else 2."""
    names = ["realToInteger.y", "sum.y", "product.y", "triggeredAdd.y", "multiSwitch1.y"]
    out = _simulate("Modelica.Blocks.Examples.IntegerNetwork1", names, tmp_path)
    t = out["time"]
    u = 3 * np.sin(2 * np.pi * 0.1 * t)
    rounded = np.where(u > 0, np.floor(u + 0.5), np.ceil(u - 0.5))
    step = np.where(t >= 2, 3, 0)
    total = rounded + step + 1
    switch = np.where((t % 1) < 0.5, 4, np.where((t % 2) < 1.6, 6, 2))
    ok = (np.abs(np.abs(u - np.trunc(u)) - 0.5) > 0.02) & _away(t, [*np.arange(0, 11, 0.5), *(np.arange(0, 11, 2) + 1.6)])
    expected = {"realToInteger.y": rounded, "sum.y": total, "product.y": total * step,
                "triggeredAdd.y": np.floor(t + 1e-9), "multiSwitch1.y": switch}
    for name, want in expected.items():
        assert np.array_equal(out[name][ok], want[ok].astype(float)), name
