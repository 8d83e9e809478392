"""The model's algebraic loops start Newton from their last converged solution, and a root outside a
tearing variable's declared min/max counts as no solution (issue 35: MSL
``Fluid.Examples.IncompressibleFluidNetwork``, whose medium loop found, from the density's start value,
a second root with a negative density once the trajectory had moved on). The expectations are hand-worked:
closed forms of small models whose loop has two roots, and scipy's ``solve_ivp`` on the same ODE with the
physical root written out."""
from __future__ import annotations

import casadi as ca
import fmpy
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from trackingbox.compiler import compile_model
from trackingbox.compiler.loop_solve import warm_solution

pytestmark = pytest.mark.compile

# y^2 - s*y - 2*s^2 = (y - 2*s)*(y + s): the roots 2*s (y >= 0: the physical one) and -s. Newton on a
# quadratic goes to the root on the guess's side of their midpoint s/2: from y.start = 1 to 2*s while
# s < 2, to -s after. With der(s) = 0.1*y on the physical root s = exp(0.2*t), past 2 at t = 5*ln 2.
TWO_ROOTS = """model TwoRoots "y solves y^2 - s*y - 2*s^2 = 0: roots 2*s (y >= 0) and -s"
  Real s(start = 1, fixed = true);
  Real y(start = 1, min = 0);
  discrete Real n(start = 0, fixed = true) "s's crossings of 2 (a when-clause beside the loop)";
equation
  der(s) = 0.1*y;
  y^2 - s*y - 2*s^2 = 0;
  when s > 2 then
    n = pre(n) + 1;
  end when;
end TwoRoots;
"""

# (y - a)*(y - b) = 0 with (a, b) = (8, -1) before t = 1 and (1, 12) after; y in [0, 10]: y = 8, then 1.
# From y.start = 5 Newton reaches 8 (midpoint 3.5), then 1 (midpoint 6.5); from the last solution 8
# it reaches 12, above max: the start value's root is taken instead. s = integral of y.
ROOT_JUMP = """model RootJump "the physical root of (y - a)*(y - b) = 0 jumps at t = 1"
  Real y(start = 5, min = 0, max = 10);
  Real a = if time < 1 then 8 else 1;
  Real b = if time < 1 then -1 else 12;
  Real s(start = 0, fixed = true);
equation
  (y - a)*(y - b) = 0;
  der(s) = y;
end RootJump;
"""


def _fmu(tmp_path, name: str, text: str) -> str:
    src = tmp_path / f"{name}.mo"
    src.write_text(text)
    return str(compile_model(src, name, backend="embedded", output=tmp_path / f"{name}.fmu").fmu)


def test_a_loop_follows_its_root_along_the_trajectory(tmp_path):
    """TwoRoots to t = 10 (s = e^2 = 7.39, far past where the start value's Newton falls on y = -s):
    y = 2 s and s = exp(0.2 t), and the same from scipy's solve_ivp on ds/dt = 0.1 * 2 s; the when-clause
    fires once, at s = 2 (t = 5 ln 2)."""
    out = fmpy.simulate_fmu(_fmu(tmp_path, "TwoRoots", TWO_ROOTS), stop_time=10.0, output_interval=0.5,
                            relative_tolerance=1e-8, output=["s", "y", "n"])
    t = out["time"]
    away = np.abs(t - 5 * np.log(2)) > 1e-4  # (the event, found to the solver's tolerance, is recorded twice)
    assert np.array_equal(out["n"][away], np.where(t[away] > 5 * np.log(2), 1.0, 0.0))
    assert t[-1] == pytest.approx(10.0)
    assert np.allclose(out["s"], np.exp(0.2 * t), rtol=1e-5, atol=0)
    assert np.allclose(out["y"], 2 * out["s"], rtol=1e-9, atol=0)
    ref = solve_ivp(lambda _t, s: 0.1 * (s + np.sqrt(s * s + 8 * s * s)) / 2, (0, 10), [1.0], dense_output=True,
                    rtol=1e-10, atol=1e-12)  # the root y >= 0 of y^2 - s y - 2 s^2 by the quadratic formula
    assert np.allclose(out["s"], ref.sol(t)[0], rtol=1e-5, atol=0)


def test_a_root_outside_the_bounds_falls_back_to_the_start_values(tmp_path):
    """RootJump to t = 2: y = 8 before t = 1, then 1 (the last solution's Newton gives 12 > max = 10),
    so s(t) = 8 t, then 8 + (t - 1); at t = 2, s = 9 (20 with y = 12)."""
    out = fmpy.simulate_fmu(_fmu(tmp_path, "RootJump", ROOT_JUMP), stop_time=2.0, output_interval=0.25,
                            relative_tolerance=1e-8, output=["s", "y"])
    t, y, s = out["time"], out["y"], out["s"]
    assert np.allclose(y[t < 0.99], 8.0, rtol=0, atol=1e-9)
    assert np.allclose(y[t > 1.01], 1.0, rtol=0, atol=1e-9)
    assert s[-1] == pytest.approx(9.0, rel=1e-6)


def _solved(g, z, p, memory, start, value, lower, upper) -> float:
    m, pv = ca.MX.sym("m"), ca.MX.sym("pv")
    f = ca.Function("f", [m, pv], [warm_solution("t", z, p, g, m, ca.DM([start]), pv, [lower], [upper])])
    return float(f(memory, value))


@pytest.mark.parametrize(("memory", "start", "expected"), [
    (2.3, 1.0, 2.0),    # Newton from the memory: the root beside it
    (0.4, 1.0, 2.0),    # from the memory to -1 (below min = 0), from the start value to 2
    (-0.5, -0.5, -1.0),  # both guesses to -1, and no fallback reaches 2: the root outside rather than none
])
def test_the_warm_start_prefers_a_root_inside_the_bounds(memory, start, expected):
    """(z - 2)(z + 1) = z^2 - p z - 2 p^2 at p = 1, z >= 0 (roots hand-worked)."""
    z, p = ca.MX.sym("z"), ca.MX.sym("p")
    assert _solved(z ** 2 - p * z - 2 * p ** 2, z, p, memory, start, 1.0, 0.0, np.inf) == pytest.approx(expected,
                                                                                                         abs=1e-9)


def test_a_loop_without_a_root_stays_nan():
    z, p = ca.MX.sym("z"), ca.MX.sym("p")
    assert np.isnan(_solved(z ** 2 + p, z, p, 0.5, 0.5, 1.0, -np.inf, np.inf))


def test_a_warm_guess_within_the_residual_tolerance_still_moves():
    """1e-6 (z - p) = 0 from z = 1 at p = 1 + 1e-5: the guess's residual, 1e-11, is below the
    rootfinders' 1e-10, so a Newton that tests the residual first would keep z = 1; the solution is p."""
    z, p = ca.MX.sym("z"), ca.MX.sym("p")
    assert _solved(1e-6 * (z - p), z, p, 1.0, 1.0, 1 + 1e-5, -np.inf, np.inf) == pytest.approx(1 + 1e-5, rel=1e-14)


def test_a_warm_newton_in_pascal_stops_at_its_root():
    """(z / 1e5)^3 - p = 0 near 2e5 Pa (a residual whose rounding stays above 1e-10): from a guess 1 % off,
    the root (p)^(1/3) 1e5, hand-worked, to 1e-13."""
    z, p = ca.MX.sym("z"), ca.MX.sym("p")
    g = 1e5 * ((z / 1e5) ** 3 - p)
    assert _solved(g, z, p, 2.02e5, 2.02e5, 8.0, 0.0, np.inf) == pytest.approx(2e5, rel=1e-13)
