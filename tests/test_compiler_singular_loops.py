"""An algebraic loop whose Jacobian is singular at its solution (issue 35: MSL
``Rotational.Examples.LossyGearDemo2``, two stuck friction elements in series whose torque split no
equation determines) is solved for the solution nearest the guess (the start values) instead of
giving NaN; a loop with a regular Jacobian keeps Newton's solution where Newton converges; where
Newton's steps swing across the root of a square-root law, a damped iteration's end is where the
solution is sought; where no solution is near, the loop stays NaN. The expectations: numpy's pseudo-inverse,
z0 + pinv(A) (b - A z0) for A z = b, and the point of a circle nearest a given one."""
from __future__ import annotations

import casadi as ca
import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.compiler.flat_systems import _or_nearest_solution

pytestmark = pytest.mark.compile

SINGULAR = """model Singular "a consistent linear loop of rank 1 (time-varying coefficients: not torn)"
  parameter Real b = 3;
  Real x(start = 1);
  Real y(start = -2);
  Real s(start = 0, fixed = true);
equation
  der(s) = 1;
  (1 + time)*x + (1 + time)*y = (1 + time)*b;
  2*(1 + time)*x + 2*(1 + time)*y = 2*(1 + time)*b + RHS;
end Singular;
"""


def _compile(tmp_path, rhs: str):
    src = tmp_path / "Singular.mo"
    src.write_text(SINGULAR.replace("RHS", rhs))
    return compile_model(src, "Singular", backend="embedded", output=tmp_path / "s.fmu")


def _solve(g, z, p, guess, value):
    """(Newton's iterate, the loop's solution) of g(z, p) = 0 from *guess*, evaluated by CasADi."""
    rf = ca.rootfinder("r", "fast_newton", {"x": z, "p": p, "g": g},
                       {"abstol": 1e-10, "max_iter": 100, "error_on_fail": False})  # as the exported C: no error
    z0, pv = ca.MX.sym("z0", z.numel()), ca.MX.sym("pv", p.numel())
    newton = rf(z0, pv)
    f = ca.Function("f", [z0, pv], [newton, _or_nearest_solution("t", z, p, g, newton, z0, pv)])
    a, b = f(guess, value)
    return np.array(a).ravel(), np.array(b).ravel()


@pytest.mark.parametrize("guess", [[1.0, -2.0], [0.3, 0.1], [5.0, 5.0], [-4.0, 0.0]])
def test_a_singular_linear_loop_gives_the_solution_nearest_the_guess(guess):
    z, p = ca.MX.sym("z", 2), ca.MX.sym("p")
    newton, sol = _solve(ca.vertcat(z[0] + z[1] - p, 2 * (z[0] + z[1] - p)), z, p, guess, 3.0)
    assert not np.all(np.isfinite(newton))  # Newton's step divides by the zero pivot
    a, b, z0 = np.array([[1.0, 1.0], [2.0, 2.0]]), np.array([3.0, 6.0]), np.array(guess)
    assert np.allclose(sol, z0 + np.linalg.pinv(a) @ (b - a @ z0), atol=1e-8)


@pytest.mark.parametrize("guess", [[1.0, -2.0], [0.3, 0.1], [5.0, 5.0]])
def test_a_singular_nonlinear_loop_gives_the_point_nearest_the_guess(guess):
    """x^2 + y^2 = 3 stated twice: the nearest point of the circle lies on the ray through the guess."""
    z, p = ca.MX.sym("z", 2), ca.MX.sym("p")
    circle = z[0] ** 2 + z[1] ** 2 - p
    _, sol = _solve(ca.vertcat(circle, 2 * circle), z, p, guess, 3.0)
    assert np.allclose(sol, np.sqrt(3.0) * np.array(guess) / np.linalg.norm(guess), atol=1e-7)


@pytest.mark.parametrize("guess", [[1e5, 1e5], [2e5, 0.5e5]])
def test_a_singular_loop_in_pascal_with_flows_in_kg_per_s_gives_the_nearest_solution(guess):
    """Two ports' flow balances in two pressures, k*(pa - pb - dp) and -2 times it, k = 4e-6 kg/s/Pa
    (an overflow pipe between two ports above their levels: only the pressure difference dp = 5e4 Pa
    is determined). The nearest solution moves each pressure by half the gap: for the guess (1e5, 1e5),
    pa = 1.25e5, pb = 0.75e5. Unscaled, eps = 1e-10 against J J' = 1.6e-10 held the regularised
    solution 38 % of the way from a root, and the loop gave NaN."""
    z, p = ca.MX.sym("z", 2), ca.MX.sym("p")
    flow = 4e-6 * (z[0] - z[1] - p)
    newton, sol = _solve(ca.vertcat(flow, -2 * flow), z, p, guess, 5e4)
    assert not np.all(np.isfinite(newton))  # the zero pivot: the fallback answers
    gap = (guess[0] - guess[1] - 5e4) / 2
    assert np.allclose(sol, [guess[0] - gap, guess[1] + gap], rtol=0, atol=1e-4)


def test_a_square_root_law_that_newton_swings_across_gives_the_nearest_solution():
    """A turbulent flow law, k*d/sqrt(|d| + 1) of d = pa - pb - 5e4 Pa (k = 4.5e-5: ~0.01 kg/s at the
    guess), stated twice: Newton on a square-root law overshoots to about -d each step and creeps in
    by ~2 Pa per step, so 100 steps end ~5e4 Pa from the root with a residual of ~0.01 kg/s (below
    1e-6*(1 + |z|) for pressures ~1e5 Pa, but far from a root as a distance in z), and Newton's steps
    on the nearest solution's conditions swing the same way. The damped iteration's start gives the
    nearest solution, each pressure moved by half the gap: pa = 1.25e5, pb = 0.75e5."""
    z, p = ca.MX.sym("z", 2), ca.MX.sym("p")
    d = z[0] - z[1] - p
    flow = 4.5e-5 * d / ca.sqrt(ca.fabs(d) + 1)
    newton, sol = _solve(ca.vertcat(flow, -2 * flow), z, p, [1e5, 1e5], 5e4)
    assert not np.all(np.isfinite(newton))
    assert np.allclose(sol, [1.25e5, 0.75e5], rtol=0, atol=1e-4)


def test_a_finite_newton_iterate_that_is_no_root_is_not_taken():
    """The same flow law with the downstream pressure given (a regular Jacobian): Newton's 100 steps
    swing across the root and end finite, ~0.08 kg/s from it (MSL ``Fluid.Examples.Tanks.
    TanksWithOverflow``'s overflow pipe took such an iterate for its flow); the loop's value is
    the root, pa = pb + 5e4 Pa with pb = 101325 Pa."""
    z, p = ca.MX.sym("z", 2), ca.MX.sym("p")
    d = z[0] - z[1] - p
    newton, sol = _solve(ca.vertcat(4.5e-5 * d / ca.sqrt(ca.fabs(d) + 1), z[1] - 101325), z, p, [1e5, 1e5], 5e4)
    assert np.all(np.isfinite(newton)) and abs(newton[0] - newton[1] - 5e4) > 1e3  # finite, no root
    assert np.allclose(sol, [151325.0, 101325.0], rtol=0, atol=1e-4)


def test_a_loop_without_a_solution_gives_nan():
    z, p = ca.MX.sym("z", 2), ca.MX.sym("p")
    _, sol = _solve(ca.vertcat(z[0] + z[1] - p, 2 * (z[0] + z[1] - p) - 1), z, p, [1.0, -2.0], 3.0)
    assert np.all(np.isnan(sol))


def test_a_consistent_singular_loop_in_an_fmu_is_solved_at_every_output(tmp_path):
    """Where the FMU's Newton iteration meets the zero pivot (before: NaN, the run failed) it falls
    back to the nearest solution; where roundoff lets Newton reach a solution, that one stays."""
    res = _compile(tmp_path, "0")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.05, output=["x", "y"])
    assert np.all(np.isfinite(out["x"])) and np.all(np.isfinite(out["y"]))
    assert np.allclose(out["x"] + out["y"], 3.0, atol=1e-8)
    # at t = 0 the pivot is exactly zero: the nearest solution to the start values (1, -2)
    assert np.allclose([out["x"][0], out["y"][0]], [3.0, 0.0], atol=1e-8)


def test_a_regular_loop_keeps_newtons_solution(tmp_path):
    src = tmp_path / "Regular.mo"
    src.write_text("model Regular\n  Real x(start = 1);\n  Real y(start = 1);\n  Real s(start = 0, fixed = true);\n"
                   "equation\n  der(s) = 1;\n  x^2 + y = 2 + time;\n  x - (1 + time)*y = 0;\nend Regular;\n")
    res = compile_model(src, "Regular", backend="embedded", output=tmp_path / "r.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25, output=["x", "y"])
    for t, x, y in zip(out["time"], out["x"], out["y"]):
        # x = (1 + t) y, x^2 + y = 2 + t: the positive root of (1 + t)^2 y^2 + y - (2 + t) = 0
        c = (1 + t) ** 2
        yy = (-1 + np.sqrt(1 + 4 * c * (2 + t))) / (2 * c)
        assert abs(y - yy) < 1e-9 and abs(x - (1 + t) * yy) < 1e-9


class _Counted(ca.Callback):
    """r(z) = z^2 + 1 (no root; |r|^2 is least at z = 0, where r = 1 and r' = 0), counting evaluations."""

    def __init__(self) -> None:
        ca.Callback.__init__(self)
        self.calls = 0
        self.construct("counted_r", {})

    def get_n_in(self) -> int:
        return 3  # z, p, z0 as a loop's scaled distance takes them

    def get_n_out(self) -> int:
        return 1

    def eval(self, args):
        self.calls += 1
        return [args[0] ** 2 + 1]

    def has_jacobian(self) -> bool:
        return True

    def get_jacobian(self, name, inames, onames, opts):
        z, p, z0, out = ca.MX.sym("z"), ca.MX.sym("p"), ca.MX.sym("z0"), ca.MX.sym("out")
        return ca.Function(name, [z, p, z0, out], [2 * z, ca.MX(1, 1), ca.MX(1, 1)], inames, onames, opts)


def test_the_damped_iteration_stops_at_a_step_no_length_improves(monkeypatch):
    """From z = 0 of r = z^2 + 1 the Gauss-Newton step is 0, so no length of it lowers |r|^2 (1 - 1e-4 a
    is below 1 for every length a): the first step tries all 24 lengths and ends the iteration, where
    each of the 60 steps did the same before. So the whole iteration evaluates r as often as its first
    step alone, and more than 23 times (the lengths 1/2**j, j = 0..22, tried; 2**-23 is taken untried).
    The end is z = 0, as before."""
    from trackingbox.compiler import loop_solve

    def calls(iterations: int) -> int:
        monkeypatch.setattr(loop_solve, "DAMPED_ITERATIONS", iterations)
        counted = _Counted()
        end = ca.Function("end", [], [loop_solve._damped_newton("t", counted, 1, ca.DM([0.0]), ca.DM([0.0]))])
        assert float(end()["o0"]) == 0.0
        return counted.calls

    one = calls(1)
    assert one >= 23 and calls(60) == one


def test_a_loop_flat_at_its_guess_is_moved_off_the_flat_point():
    """r = p - z^2 (3 for z > 0, else 4) from z = 0 (a loss that goes as a flow squared, from
    m_flow.start = 0: MSL ``Fluid.Examples.Explanatory.MomentumBalanceFittings``): r' = 0 at the guess, so
    Newton's matrix is singular and every Gauss-Newton step is zero there (NaN before). Of its roots
    sqrt(p/3) and -sqrt(p/4) (hand-worked) the loop gives the one nearer the guess; a two-unknown loop
    whose flow column alone is zero at the guess, the same."""
    z, p = ca.MX.sym("z", 1), ca.MX.sym("p")
    newton, sol = _solve(p - z ** 2 * ca.if_else(z > 0, 3, 4), z, p, [0.0], 1e4)
    assert not np.all(np.isfinite(newton))
    assert abs(sol[0] + np.sqrt(1e4 / 4)) < 1e-8
    z2 = ca.MX.sym("z", 2)  # (flow, pressure): p2 = 1e5 + 3 m |m| and p2 = 1.2e5
    _, sol2 = _solve(ca.vertcat(z2[1] - 1e5 - 3 * z2[0] * ca.fabs(z2[0]), z2[1] - p), z2, p, [0.0, 1e5], 1.2e5)
    assert np.allclose(sol2, [np.sqrt(2e4 / 3), 1.2e5], rtol=1e-9, atol=0)


def test_a_flow_loop_started_at_zero_flow_simulates(tmp_path):
    """The same in an FMU, each output solved again from m.start = 0: 0.5 m^2 k = dp with a loss
    coefficient k = -6 for m > 0 and -8 for m < 0 (a sudden expansion's total-pressure balance, MSL
    ``Fittings``, inside a function: no event freezes the relation) and dp = -1e4 (1 + t): roots
    sqrt(1e4 (1 + t) / 3) and -sqrt(1e4 (1 + t) / 4), the second nearer the guess (hand-worked)."""
    src = tmp_path / "FlatStart.mo"
    src.write_text("model FlatStart\n  Real m(start = 0);\n  Real s(start = 0, fixed = true);\nequation\n"
                   "  der(s) = 1;\n  -1e4*(1 + time) = 0.5*m^2*noEvent(if m > 0 then -6 else -8);\nend FlatStart;\n")
    res = compile_model(src, "FlatStart", backend="embedded", output=tmp_path / "f.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25, output=["m"])
    assert np.allclose(out["m"], -np.sqrt(1e4 * (1 + out["time"]) / 4), rtol=1e-9, atol=0)
