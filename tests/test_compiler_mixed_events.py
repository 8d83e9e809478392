"""The event iteration solves each step's mixed system (MLS 8.6): ``pre(v)`` is held at the value
before the step while the relations are evaluated at the continuous-time values of the current
iterate, and the step is repeated until ``pre(v) == v``. The MSL's friction elements depend on it:
their ``locked``/``startForward``/``startBackward`` follow from the path torque ``sa``, which follows
from them and from ``pre(mode)``. Before, a step re-evaluated the continuous part with ``pre(v) = v``
and the MSL's ``Rotational.Examples.Friction`` switched its clutch between sticking and sliding until
the chattering stop ended the run at t = 0.0068 s.

Checked against independent expectations: an inertia on a bearing with stiction driven by a
sinusoidal torque against a piecewise scipy solution (stuck while the torque is inside the
break-away torque, sliding against the Coulomb torque otherwise); the MSL's ``Friction`` example
against the closed forms of its phases (the motor inertia decelerated by the sliding clutch's
constant torque, the two coupled inertias on the spring once the brake and the clutch stick) and
the friction laws; a mixed system without a consistent solution stops with an error naming it.
"""
from __future__ import annotations

import fmpy
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile


STICK = """model Stick "an inertia on a bearing with stiction, driven by a sinusoidal torque"
  Modelica.Mechanics.Rotational.Components.Inertia inertia(J = 0.5, phi(start = 0, fixed = true),
    w(start = 0, fixed = true));
  Modelica.Mechanics.Rotational.Components.BearingFriction bearing(tau_pos = [0, 1.2; 10, 2.2], peak = 1.25);
  Modelica.Mechanics.Rotational.Sources.Torque torque;
  Modelica.Blocks.Sources.Sine sine(amplitude = 2, f = 0.5);
equation
  connect(sine.y, torque.tau);
  connect(torque.flange, inertia.flange_a);
  connect(inertia.flange_b, bearing.flange_a);
end Stick;
"""

J, F = 0.5, 0.5  # the inertia; the torque's frequency
COULOMB, SLOPE, BREAKAWAY = 1.2, 0.1, 1.5  # tau_pos(w) = 1.2 + 0.1 |w|, peak 1.25 -> 1.5 at rest


def _stick_slip(amplitude: float, stop: float) -> list[tuple[float, float, int, object]]:
    """The reference: (t0, t1, mode, phi or dense solution) pieces; stuck until |T| exceeds the
    break-away torque, then sliding until w returns to 0, where it sticks again if |T| is below it."""
    def torque(t):
        return amplitude * np.sin(2 * np.pi * F * t)

    t, phi, mode, pieces = 0.0, 0.0, 0, []
    while t < stop - 1e-12:
        if mode == 0:
            grid = np.linspace(t, stop, int((stop - t) * 2000) + 2)
            over = np.abs(torque(grid)) - BREAKAWAY
            k = next((i for i in range(1, grid.size) if over[i] > 0 >= over[i - 1]), None)
            if k is None:
                pieces.append((t, stop, 0, phi))
                break
            t1 = brentq(lambda x: abs(torque(x)) - BREAKAWAY, grid[k - 1], grid[k], xtol=1e-14)
            pieces.append((t, t1, 0, phi))
            t, mode = t1, 1 if torque(t1) > 0 else -1
            continue
        d, t0 = mode, t

        def rhs(x, y, d=d):
            return [y[1], (torque(x) - d * (COULOMB + SLOPE * abs(y[1]))) / J]

        def stopped(x, y, d=d, t0=t0):
            return y[1] if x > t0 + 1e-9 else d
        stopped.terminal, stopped.direction = True, -d
        sol = solve_ivp(rhs, (t, stop), [phi, 0.0], events=stopped, rtol=1e-11, atol=1e-13, dense_output=True)
        pieces.append((t, sol.t[-1], d, sol.sol))
        t, phi = sol.t[-1], sol.y[0, -1]
        mode = (1 if torque(t) > 0 else -1) if abs(torque(t)) > BREAKAWAY else 0
    return pieces


def _at(pieces, times):
    phi, w, mode = np.zeros_like(times), np.zeros_like(times), np.zeros_like(times)
    for i, x in enumerate(times):
        for a, b, m, sol in pieces:
            if a <= x <= b:
                mode[i] = m
                if m == 0:
                    phi[i] = sol
                else:
                    phi[i], w[i] = sol(x)
                break
    return phi, w, mode


@pytest.fixture(scope="module")
def stick_fmu(tmp_path_factory):
    need_msl()
    tmp = tmp_path_factory.mktemp("stick")
    (tmp / "Stick.mo").write_text(STICK)
    return compile_model(tmp / "Stick.mo", "Stick", backend="embedded", output=tmp / "stick.fmu",
                         libraries=[MSL]).fmu


@pytest.mark.parametrize("amplitude", [2.0, 2.5])
def test_bearing_friction_sticks_and_slides_as_the_piecewise_solution(stick_fmu, amplitude):
    """2.0: stuck, forward, stuck (|T| < 1.5 where w returns to 0), backward, ...; 2.5: the torque is
    beyond the break-away torque where w returns to 0, so the inertia reverses without sticking."""
    pieces = _stick_slip(amplitude, 6.0)
    modes = [m for _, _, m, _ in pieces]
    assert modes[:4] == ([0, 1, 0, -1] if amplitude == 2.0 else [0, 1, -1, 1])
    out = fmpy.simulate_fmu(str(stick_fmu), stop_time=6.0, output_interval=0.001, relative_tolerance=1e-8,
                            start_values={"sine.amplitude": amplitude},
                            output=["inertia.phi", "inertia.w", "bearing.mode", "bearing.tau"])
    t = out["time"]
    phi, w, mode = _at(pieces, t)
    assert np.abs(out["inertia.phi"] - phi).max() < 1e-5
    assert np.abs(out["inertia.w"] - w).max() < 1e-5
    switches = np.array([a for a, _, _, _ in pieces[1:]])
    away = np.min(np.abs(t[:, None] - switches[None, :]), axis=1) > 2e-3
    assert np.array_equal(out["bearing.mode"][away], mode[away])
    sliding = away & (mode != 0)
    expected = mode[sliding] * (COULOMB + SLOPE * np.abs(w[sliding]))
    assert np.allclose(out["bearing.tau"][sliding], expected, atol=1e-5)


@pytest.fixture(scope="module")
def friction_run(tmp_path_factory):
    need_msl()
    tmp = tmp_path_factory.mktemp("friction")
    fmu = compile_model(MSL, "Modelica.Mechanics.Rotational.Examples.Friction", backend="embedded",
                        output=tmp / "friction.fmu").fmu
    names = ["clutch.mode", "clutch.tau", "clutch.w_relfric", "clutch.tau0_max", "brake.mode", "brake.tau",
             "brake.w_relfric", "brake.tau0_max", "inertia1.w", "inertia2.w", "inertia3.w", "spring.phi_rel",
             "tMotor"]
    return fmpy.simulate_fmu(str(fmu), stop_time=3.0, output_interval=0.001, relative_tolerance=1e-8,
                             output=names)


def test_msl_friction_runs_to_its_end_with_the_friction_laws_holding(friction_run):
    out = friction_run
    t = out["time"]
    assert t[-1] == pytest.approx(3.0)
    for element in ("clutch", "brake"):
        mode, tau, w = out[f"{element}.mode"], out[f"{element}.tau"], out[f"{element}.w_relfric"]
        stuck = mode == 0
        assert np.abs(w[stuck]).max() < 1e-6
        assert np.all(np.abs(tau[stuck]) <= out[f"{element}.tau0_max"][stuck] * (1 + 1e-6) + 1e-9)
        sliding = (np.abs(mode) == 1) & (np.abs(w) > 1e-3)
        assert np.all(np.sign(tau[sliding]) == np.sign(w[sliding]))  # friction opposes the motion
    # the clutch sticks for good once inertia3 has come down to inertia2's speed (t about 1.66 s)
    assert np.all(out["clutch.mode"][t > 1.8] == 0) and np.all(out["brake.mode"][t > 1.0] == 0)


def test_msl_friction_phases_follow_their_closed_forms(friction_run):
    out = friction_run
    t = out["time"]
    # after 0.5 s the motor torque is 0 and the brake holds inertia1; while the clutch slides
    # backward (inertia3 faster) its torque is mu*fn = 0.5*160 N m: inertia3 (J = 1) slows at 80 rad/s^2
    sliding = (out["clutch.mode"] == -1) & (t > 0.85) & (out["brake.mode"] == 0)
    window = t[sliding]
    assert window.size > 100 and np.all(np.abs(out["tMotor"][sliding]) < 1e-9)
    slope = np.polyfit(window, out["inertia3.w"][sliding], 1)[0]
    assert slope == pytest.approx(-80.0, rel=1e-6)
    # clutch and brake stuck: inertia2 and inertia3 (J = 0.05 + 1) on the spring-damper (c = 160,
    # d = 1) against the held inertia1, a damped oscillator from the state at 2 s
    later = t >= 2.0
    t0 = t[later][0]
    phi0, w0 = out["spring.phi_rel"][later][0], out["inertia2.w"][later][0]
    # y = (spring.phi_rel = phi1 - phi2, w2): phi_rel' = -w2, 1.05 w2' = 160 phi_rel + 1 (0 - w2)
    ref = solve_ivp(lambda _, y: [-y[1], (160 * y[0] - y[1]) / 1.05],
                    (t0, 3.0), [phi0, w0], t_eval=t[later], rtol=1e-10, atol=1e-12)
    assert np.allclose(out["inertia2.w"][later], out["inertia3.w"][later], atol=1e-6)
    assert np.abs(out["inertia2.w"][later] - ref.y[1]).max() < 1e-4 * max(1.0, np.abs(ref.y[1]).max())


def test_a_mixed_system_without_a_consistent_solution_stops_with_an_error(tmp_path):
    """b = x > 0 with x = if b then -1 else 1 has no solution: the passes of each step cycle, no value
    of the relation is consistent, each step falls back to its first pass, the steps flip b for ever,
    and initialisation fails after 100 steps saying so instead of looping."""
    src = tmp_path / "NoSolution.mo"
    src.write_text("model NoSolution\n  Real y(start = 0, fixed = true);\n  Real x;\n  Boolean b;\nequation\n"
                   "  b = x > 0;\n  x = if b then -1 else 1;\n  der(y) = x;\nend NoSolution;\n")
    fmu = compile_model(src, "NoSolution", backend="embedded", output=tmp_path / "n.fmu").fmu
    messages: list[str] = []

    def logger(*args):
        messages.append(args[-1].decode() if isinstance(args[-1], bytes) else str(args[-1]))

    with pytest.raises(Exception, match="fmi3ExitInitializationMode"):
        fmpy.simulate_fmu(str(fmu), stop_time=1.0, logger=logger)
    assert any("t = 0 s did not converge after 100 steps (100 of them with discrete variables that do not "
               "settle: a mixed system of discrete and continuous equations without a consistent solution)" in m
               for m in messages), messages


def test_msl_heat_losses_dissipates_in_every_element(tmp_path):
    """HeatLosses: a lossy gear (its bindings through Vectors.interpolate computed at initialisation,
    test_compiler_asserting_bindings), a one-way clutch whose startForward needs the pre value of the
    step before (a step without a consistent solution falls back to its first pass), a clutch, a
    brake and a bearing. Over its experiment every element's loss power is >= 0 (the second law),
    and the friction elements both stick and slide."""
    need_msl()
    fmu = compile_model(MSL, "Modelica.Mechanics.Rotational.Examples.HeatLosses", backend="embedded",
                        output=tmp_path / "hl.fmu").fmu
    md = fmpy.read_model_description(str(fmu))
    losses = [v.name for v in md.modelVariables if v.name.endswith(".lossPower")]
    modes = ["lossyGear.mode", "clutch.mode", "brake.mode", "bearingFriction.mode"]
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.0005, relative_tolerance=1e-8,
                            output=losses + modes + ["oneWayClutch.stuck"])
    assert out["time"][-1] == pytest.approx(1.0) and len(losses) == 8
    for name in losses:
        assert out[name].min() > -1e-8, name
        assert out[name].max() > 1e-3, name  # each element dissipates at some time
    for name in modes:
        seen = set(np.unique(out[name]))
        assert 0.0 in seen and seen & {1.0, -1.0}, name  # stuck and sliding
    assert set(np.unique(out["oneWayClutch.stuck"])) == {0.0, 1.0}
