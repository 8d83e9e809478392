"""``while`` statements in functions (issue 35, item 2): compiled by the embedded backend with their
Modelica meaning (:mod:`trackingbox.compiler.while_loops`, :mod:`trackingbox.compiler.while_source`)
and checked against the same algorithms written in Python or against math/scipy; a loop that does not
end within the passes the compiler unrolls stops the model with an error naming the loop."""
from __future__ import annotations

import math
import re
import zipfile

import fmpy
import numpy as np
import pytest
from _fixtures_msl import need_msl
from scipy import signal
from scipy.optimize import brentq

from trackingbox.compiler import compile_model, while_calls
from trackingbox.compiler.while_loops import MAX_CONSTANT_PASSES, MAX_PASSES
from trackingbox.compiler.while_source import while_loops_as_for
from trackingbox.errors import AssertionFailed, UnsupportedConstructError
from trackingbox.fmu import FMUModel

pytestmark = pytest.mark.compile

MODELS = """
package Wh
  function newtonSqrt "Newton's square root: a counter bounds the loop"
    input Real a;
    input Real tol = 1e-12;
    output Real x;
  protected
    Integer i;
  algorithm
    x := max(a, 1);
    i := 0;
    while abs(x*x - a) > tol*a and i < 60 loop
      x := 0.5*(x + a/x);
      i := i + 1;
    end while;
  end newtonSqrt;
  function sumOfSquares "1^2 + ... + k^2 for the k that first reaches n: the count follows the input"
    input Real n;
    output Real s;
  protected
    Real k;
  algorithm
    k := 0;
    s := 0;
    while k < n loop
      k := k + 1;
      s := s + k*k;
    end while;
  end sumOfSquares;
  function bisect "root of u^3 + u - a by bisection: nothing bounds the loop but its convergence"
    input Real a;
    input Real tol = 1e-10;
    output Real u;
  protected
    Real lo;
    Real hi;
  algorithm
    u := 0;
    lo := 0;
    hi := max(1, a);
    while hi - lo > tol loop
      u := (lo + hi)/2;
      if u^3 + u > a then
        hi := u;
      else
        lo := u;
      end if;
    end while;
    u := (lo + hi)/2;
  end bisect;
  function collatz "steps of the Collatz sequence from n to 1: a constant condition, iterated concretely"
    input Integer n;
    output Integer steps;
  protected
    Integer m;
  algorithm
    m := n;
    steps := 0;
    while m <> 1 loop
      m := if mod(m, 2) == 0 then div(m, 2) else 3*m + 1;
      steps := steps + 1;
    end while;
  end collatz;
  function powerAbove "the first power of two above a: the output is assigned only where the loop ends"
    input Real a;
    output Real p;
  protected
    Real k;
    Boolean found;
  algorithm
    k := 1;
    found := false;
    while not found loop
      k := 2*k;
      if k > a then
        found := true;
        p := k;
      end if;
    end while;
  end powerAbove;
  function halvings "how often a halves before it is below 1: an assert in the body, checked on every pass"
    input Real a;
    input Real limit;
    output Integer n;
  protected
    Real v;
  algorithm
    v := a;
    n := 0;
    while v >= 1 loop
      assert(n < limit, "halvings: more than the limit");
      v := v/2;
      n := n + 1;
    end while;
  end halvings;
  model Halving
    parameter Real limit = 100;
    Real x(start = 0.5, fixed = true);
    Real h = halvings(2^(3*x), limit);
  equation
    der(x) = 1;
  end Halving;
  model Loops
    parameter Real rate = 1;
    Real x(start = 0.5, fixed = true);
    Real r;
    Real s;
    Real b;
    Real c;
    Real p;
  equation
    der(x) = rate;
    r = newtonSqrt(x);
    s = sumOfSquares(x);
    b = bisect(x);
    c = collatz(27);
    p = powerAbove(x);
  end Loops;
end Wh;
"""


@pytest.fixture(scope="module")
def loops_fmu(tmp_path_factory):
    d = tmp_path_factory.mktemp("while")
    src = d / "Wh.mo"
    src.write_text(MODELS)
    return src, compile_model(src, "Wh.Loops", backend="embedded", output=d / "loops.fmu").fmu


def _sum_of_squares(n: float) -> float:
    k = s = 0.0
    while k < n:
        k += 1
        s += k * k
    return s


def _power_above(a: float) -> float:
    k = 1.0
    while True:
        k *= 2
        if k > a:
            return k


def _collatz(n: int) -> int:
    steps = 0
    while n != 1:
        n = n // 2 if n % 2 == 0 else 3 * n + 1
        steps += 1
    return steps


def test_while_loops_match_the_same_algorithms_in_python(loops_fmu):
    _, fmu = loops_fmu
    # the output grid avoids integer x, where sumOfSquares steps
    out = fmpy.simulate_fmu(str(fmu), stop_time=6.0, output_interval=0.25, output=["x", "r", "s", "b", "c", "p"],
                            relative_tolerance=1e-9, record_events=False)
    x = out["x"]
    assert np.allclose(x, 0.5 + out["time"], atol=1e-8)
    assert np.allclose(out["r"], [math.sqrt(v) for v in x], rtol=1e-10)
    interior = np.abs(x - np.round(x)) > 1e-6
    assert interior.sum() >= 12
    assert np.array_equal(out["s"][interior], [_sum_of_squares(v) for v in x[interior]])
    assert np.allclose(out["b"], [brentq(lambda u, a=v: u**3 + u - a, 0.0, max(1.0, v), xtol=1e-13) for v in x],
                       atol=1e-9)
    assert np.array_equal(out["p"][interior], [_power_above(v) for v in x[interior]])
    assert np.all(out["c"] == _collatz(27))  # 111 passes: beyond the unrolling bound, yet constant


def test_a_loop_that_does_not_end_within_its_bound_stops_the_model_naming_it(loops_fmu):
    src, fmu = loops_fmu
    # sumOfSquares(x) takes ceil(x) passes: past x = MAX_PASSES the unrolled loop has not ended, and the
    # run stops there (asserts are checked at each communication point) instead of giving a wrong sum
    line = MODELS.splitlines().index("    while k < n loop") + 1
    with pytest.raises(AssertionFailed, match=rf"the while loop at {re.escape(str(src))}:{line} in function "
                       rf"'sumOfSquares' did not end within {MAX_PASSES} passes") as exc:
        FMUModel(fmu).simulate(stop_time=2.0, output_interval=0.1, parameters={"rate": 60.0}, outputs=["s"])
    t = float(re.search(r"at t = ([0-9.]+) s", str(exc.value)).group(1))
    assert 0.5 + 60.0 * (t - 0.1) <= MAX_PASSES < 0.5 + 60.0 * t + 1e-9  # the first point past x = 100


def test_an_assert_in_a_loop_body_counts_on_every_pass_taken(tmp_path):
    """The folded loop (:mod:`trackingbox.compiler.while_fold`) keeps an assert of its body as a flag
    over the passes taken: halvings(2^(3x)) takes floor(3x) + 1 passes for x >= 0 (Python's count), and
    with limit = 10 the assert fails at the first pass with n = 10, i.e. where 3x reaches 10."""
    src = tmp_path / "Wh.mo"
    src.write_text(MODELS)
    fmu = compile_model(src, "Wh.Halving", backend="embedded", output=tmp_path / "h.fmu").fmu

    def count(a: float) -> int:
        n = 0
        while a >= 1:
            a, n = a / 2, n + 1
        return n
    out = FMUModel(fmu).simulate(stop_time=3.0, output_interval=0.1, outputs=["x", "h"])
    interior = np.abs(3 * out["x"] - np.round(3 * out["x"])) > 1e-6
    assert interior.sum() >= 15
    assert np.array_equal(out["h"][interior], [count(2 ** (3 * v)) for v in out["x"][interior]])
    with pytest.raises(AssertionFailed, match="halvings: more than the limit") as exc:
        FMUModel(fmu).simulate(stop_time=3.0, output_interval=0.1, parameters={"limit": 10.0}, outputs=["h"])
    t = float(re.search(r"at t = ([0-9.]+) s", str(exc.value)).group(1))
    assert 10 / 3 - 0.5 - 1e-9 <= t < 10 / 3 - 0.5 + 0.1 + 1e-9


def test_the_source_rewrite_keeps_lines_and_nesting():
    src = (b"algorithm\n  while a < 1 // first\n    and b loop\n    while c loop\n      c := false;\n"
           b"    end while;\n  a := \"while x loop\";\n  end  while ;\n")
    out, lines = while_loops_as_for(src)
    assert lines == [4, 2]
    assert out.count(b"\n") == src.count(b"\n")
    text = out.decode()
    assert text.count("for _while_line_") == 2 and text.count("end if; end for;") == 2
    assert "assert(not (a < 1 and b)" in text and "assert(not (c)" in text
    assert '"while x loop"' in text  # a string is never read as a loop
    assert "if a < 1" in text and "first" not in text  # a comment in the condition cannot swallow 'then'
    assert "end while" not in text


def test_a_loop_rumoca_bounds_by_its_counter_is_left_to_it():
    src = (b"  while (i < IterationData.IMAX) and not found loop\n    found := x > 1;\n    i := i + 1;\n"
           b"  end while;\n  while k < n loop\n    k := k + 1;\n  end while;\n")
    out, lines = while_loops_as_for(src)
    assert lines == [5]  # a bound that is an input: rumoca cannot prove the loop finite
    assert out.decode().startswith("  while (i < IterationData.IMAX) and not found loop")


def test_msl_critical_damping_filter_normalised_by_its_while_loops(tmp_path):
    """``Modelica.Blocks.Continuous.Filter`` (CriticalDamping, normalized): the cut-off correction is found
    by the MSL's while loops (``findInterval``, Brent's ``solveOneNonlinearEquation``,
    ``Blocks/Continuous.mo:4019``, ``:4081``), which rumoca refused. Expected independently: three equal
    poles at w with |H(j w_cut)| = 10^(-3/20), i.e. w = w_cut/sqrt(10^(3/20*2/3) - 1), and the closed-form
    step response of 1/(s/w + 1)^3."""
    msl = need_msl().parent
    src = tmp_path / "CD.mo"
    src.write_text("""model CD
  Modelica.Blocks.Sources.Step step(startTime = 0.1, offset = 0.1);
  Modelica.Blocks.Continuous.Filter f(analogFilter = Modelica.Blocks.Types.AnalogFilter.CriticalDamping,
    normalized = true, init = Modelica.Blocks.Types.Init.SteadyState,
    filterType = Modelica.Blocks.Types.FilterType.LowPass, order = 3, f_cut = 2, f_min = 1.6);
equation
  connect(step.y, f.u);
end CD;
""")
    fmu = compile_model(src, "CD", backend="embedded", output=tmp_path / "cd.fmu", libraries=[msl]).fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.05, output=["f.y"], relative_tolerance=1e-9)
    w = 2 * math.pi * 2 / math.sqrt(10 ** (3 / 20 * 2 / 3) - 1)
    tau = np.maximum(out["time"] - 0.1, 0.0)
    expected = 0.1 + 1.0 * (1 - np.exp(-w * tau) * (1 + w * tau + (w * tau) ** 2 / 2))
    assert np.allclose(out["f.y"], expected, atol=2e-5)


def test_msl_if97_region_3_inverse_iteration_matches_iapws(tmp_path):
    """``IF97_Utilities.BaseIF97.Inverses.dofpt3`` (``Media/Water/IF97_Utilities.mo:5025``): density from
    p and T in region 3 by Newton's method in ``while ((i < IterationData.IMAX) and not found)``, a loop
    rumoca bounds by its counter, folded by the translator (at most 100 passes, IMAX = 50 ends it); three
    calls, against the ``iapws`` package's IAPWS-IF97 (an independent implementation)."""
    iapws = pytest.importorskip("iapws", reason="the iapws package (a test dependency) is not installed")
    msl = need_msl().parent
    src = tmp_path / "D3.mo"
    src.write_text("""model D3
  Real T = 630 + 30*time;
  Real d[3] = {Modelica.Media.Water.IF97_Utilities.BaseIF97.Inverses.dofpt3(p = 30e6, T = T + 10*k, delp = 1e-7)
               for k in 0:2};
end D3;
""")
    fmu = compile_model(src, "D3", backend="embedded", output=tmp_path / "d3.fmu", libraries=[msl]).fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.25, output=["T", "d[1]", "d[2]", "d[3]"])
    for k in range(3):
        expected = [iapws.IAPWS97(P=30.0, T=float(t) + 10 * k) for t in out["T"]]
        assert all(s.region == 3 for s in expected)
        assert np.allclose(out[f"d[{k + 1}]"], [s.rho for s in expected], rtol=1e-7)
    # the Newton step is one CasADi function folded over the passes (compiler.while_fold), and dofpt3 one
    # function called three times (compiler.while_calls): unrolled, the 50 passes of one call gave 5.0 MB
    # of C (measured on 800881a); folded and called, 0.42 MB for one call
    with zipfile.ZipFile(fmu) as z:
        assert z.getinfo("sources/D3.c").file_size < 1_500_000


def test_msl_chebyshev_filter_matches_scipy(tmp_path):
    """``Modelica.Blocks.Continuous.Filter`` as a normalised Chebyshev I low pass (order 3, 0.5 dB ripple):
    ``ChebyshevI``'s branch-wise loops (``Blocks/Continuous.mo:2144``, read by rumoca with if-expressions,
    :mod:`trackingbox.compiler.filter_bodies`) and the normalisation's while loops. Expected independently:
    scipy's analog ``cheby1`` with its -3 dB frequency (found by brentq on |H(jw)|) placed at f_cut, and
    its step response (scipy.signal.step)."""
    msl = need_msl().parent
    src = tmp_path / "CH.mo"
    src.write_text("""model CH
  Modelica.Blocks.Sources.Step step(startTime = 0.1, offset = 0.1);
  Modelica.Blocks.Continuous.Filter f(analogFilter = Modelica.Blocks.Types.AnalogFilter.ChebyshevI,
    normalized = true, init = Modelica.Blocks.Types.Init.SteadyState,
    filterType = Modelica.Blocks.Types.FilterType.LowPass, order = 3, f_cut = 2);
equation
  connect(step.y, f.u);
end CH;
""")
    fmu = compile_model(src, "CH", backend="embedded", output=tmp_path / "ch.fmu", libraries=[msl]).fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.01, output=["f.y"], relative_tolerance=1e-9)
    b, a = signal.cheby1(3, 0.5, 1.0, analog=True)
    w3 = brentq(lambda w: abs(np.polyval(b, 1j * w) / np.polyval(a, 1j * w)) - 10 ** (-3 / 20), 1.0, 3.0)
    b, a = signal.cheby1(3, 0.5, 2 * math.pi * 2 / w3, analog=True)
    grid = np.linspace(0.0, 0.9, 901)
    _, step = signal.step((b, a), T=grid)
    expected = 0.1 + np.interp(np.maximum(out["time"] - 0.1, 0.0), grid, step)
    assert np.allclose(out["f.y"], expected, atol=1e-6)
    assert abs(out["f.y"][-1] - 1.1) < 0.02  # settled near the step's end value (an overshoot of the ripple)


def test_a_loop_whose_constant_condition_never_turns_false_is_refused_naming_it(tmp_path):
    src = tmp_path / "Forever.mo"
    src.write_text("""package Forever
  function count
    input Real a;
    output Real y;
  protected
    Integer k;
  algorithm
    k := 0;
    y := a;
    while k >= 0 loop
      k := k + 1;
    end while;
  end count;
  model M
    Real x(start = 1, fixed = true);
    Real y = count(x);
  equation
    der(x) = 1;
  end M;
end Forever;
""")
    with pytest.raises(UnsupportedConstructError, match=rf"while statement at {re.escape(str(src))}:10 in function "
                       rf"'count' whose condition stays true: it has not ended after {MAX_CONSTANT_PASSES} passes\."):
        compile_model(src, "Forever.M", backend="embedded", output=tmp_path / "f.fmu")


def test_msl_if97_rho_ph_and_t_ph_traced_once_match_iapws(tmp_path):
    """``IF97_Utilities.rho_ph`` and ``T_ph`` inline to 74 and 0.74 billion nodes of function bodies (their
    region functions called from many branches): every function of 5 000 nodes or more is traced once
    as a CasADi function and called (compiler.while_calls), so both compile. Against the ``iapws``
    package's IAPWS-IF97 at 20 MPa across regions 1, 3 (``dtofph3``'s Newton iteration), 4 (two-phase)
    and 2. Tolerances: IF97's backward equation T(p, h) agrees with the basic equations to 25 mK in
    region 1 and 10 mK in region 2 (the release's stated consistency), so the density is checked to 25 mK
    times its slope dd/dT at constant pressure (from iapws); in the two-phase region MSL's saturated
    densities at 20 MPa (on the region 3 boundary) differ from iapws's by up to 5e-4 (measured: 3.0e-4 at
    h = 2.2 MJ/kg)."""
    iapws = pytest.importorskip("iapws", reason="the iapws package (a test dependency) is not installed")
    msl = need_msl().parent
    src = tmp_path / "RH.mo"
    src.write_text("""model RH
  Real h = 1.2e6 + 2e6*time;
  Real d = Modelica.Media.Water.IF97_Utilities.rho_ph(p = 20e6, h = h);
  Real T = Modelica.Media.Water.IF97_Utilities.T_ph(p = 20e6, h = h);
end RH;
""")
    fmu = compile_model(src, "RH", backend="embedded", output=tmp_path / "rh.fmu", libraries=[msl]).fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.05, output=["h", "d", "T"])
    regions = set()
    for row in out:
        ref = iapws.IAPWS97(P=20.0, h=float(row["h"]) / 1000)
        regions.add(ref.region)
        two_phase = ref.region == 4
        assert row["T"] == pytest.approx(ref.T, abs=1e-3 if two_phase else 0.025), row["h"]
        if two_phase:
            assert row["d"] == pytest.approx(ref.rho, rel=5e-4), row["h"]
        else:  # the density at the backward equation's temperature: |dd/dT| at constant p times its 25 mK
            slope = abs(iapws.IAPWS97(P=20.0, T=ref.T + 0.01).rho - iapws.IAPWS97(P=20.0, T=ref.T - 0.01).rho) / 0.02
            assert row["d"] == pytest.approx(ref.rho, abs=slope * 0.025 + 1e-6 * ref.rho), row["h"]
    assert regions == {1, 2, 3, 4}


def test_a_function_whose_trace_is_too_large_is_refused_naming_it(tmp_path, monkeypatch):
    """A traced function whose own trace (with the small functions it calls inlined) exceeds
    ``MAX_TRACED_SIZE`` is refused before any trace, naming it (lowered here so that ``rho_ph`` passes it)."""
    monkeypatch.setattr(while_calls, "MAX_TRACED_SIZE", 100)
    msl = need_msl().parent
    src = tmp_path / "RH.mo"
    src.write_text("""model RH
  Real h = 1.5e6 + 1e5*time;
  Real d = Modelica.Media.Water.IF97_Utilities.rho_ph(p = 20e6, h = h);
end RH;
""")
    with pytest.raises(UnsupportedConstructError, match=r"call of function 'Modelica\.Media\.Water\.IF97_Utilities\."
                       r"[A-Za-z0-9_.]+', whose trace .* counts \d+ nodes"):
        compile_model(src, "RH", backend="embedded", output=tmp_path / "rh.fmu", libraries=[msl])


def test_a_function_reached_by_two_names_is_traced_once_and_keeps_its_values(tmp_path):
    """rumoca gives a function called by its short name inside its package (``f`` in ``g``; ``Medium.h``
    through a package alias) apart from the same definition by its full name (``DD.f``, ``DD.M.Medium.h``):
    one traced CasADi function serves both names (four functions in the C: f, g, h, viaH; six before),
    and every call keeps its value (Newton's square root against math.sqrt)."""
    src = tmp_path / "DD.mo"
    src.write_text("""package DD
  function f
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
  end f;
  function g
    input Real a;
    output Real y;
  algorithm
    y := f(a) + 1;
  end g;
  partial package PM
    replaceable function h = f;
    function viaH
      input Real a;
      output Real y;
    algorithm
      y := h(a) + 2;
    end viaH;
  end PM;
  package M2
    extends PM;
  end M2;
  model M
    package Medium = M2;
    Real a = 2 + time;
    Real s = f(a);
    Real t = g(a);
    Real u = Medium.viaH(a);
    Real v = Medium.h(a);
  end M;
end DD;
""")
    fmu = compile_model(src, "DD.M", backend="embedded", output=tmp_path / "dd.fmu").fmu
    with zipfile.ZipFile(fmu) as zf:
        c = "".join(zf.read(n).decode() for n in zf.namelist() if n.startswith("sources/") and n.endswith(".c"))
    assert len(set(re.findall(r"\btbx_fn\d+\b", c))) == 4
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.25, output=["a", "s", "t", "u", "v"])
    for row in out:
        root = math.sqrt(2 + float(row["time"]))
        assert row["a"] == pytest.approx(2 + float(row["time"]), rel=1e-12)
        assert (row["s"], row["t"], row["u"], row["v"]) == pytest.approx((root, root + 1, root + 2, root), rel=1e-10)
