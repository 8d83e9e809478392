"""``der(v)`` in an initial equation where ``v`` is no state (issue 35: MSL ``Fluid.Examples.HeatingSystem``'s
tank initialises ``der(medium.T) = 0`` while its states are mass and internal energy). The derivative is v's
time derivative as the model defines it: the chain rule through the states (and time) of v's causalised
expression, explicit or the solution of an algebraic loop. A variable that depends on an input is refused,
naming the equation. Expectations: hand-worked steady states and the closed-form solutions."""
from __future__ import annotations

import math

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

VESSEL = """model SteadyT "a stirred vessel: states mass and internal energy, its temperature steady at the start"
  parameter Real c = 4 "specific heat";
  parameter Real w = 2 "inflow";
  parameter Real Tin = 300 "inflow temperature";
  parameter Real Q = 800 "heating";
  parameter Real k = 0.5 "outflow per mass";
  Real m(start = 10, fixed = true);
  Real U(start = 1000);
  Real T;
initial equation
  der(T) = 0;
equation
  der(m) = w - k*m;
  der(U) = w*c*Tin - k*m*c*T + Q;
  T = U/(m*c);
end SteadyT;
"""


def _run(tmp_path, text: str, name: str, outputs: list[str]):
    src = tmp_path / f"{name}.mo"
    src.write_text(text)
    res = compile_model(src, name, backend="embedded", output=tmp_path / f"{name}.fmu")
    return fmpy.simulate_fmu(str(res.fmu), stop_time=2.0, output_interval=0.5, output=outputs,
                             relative_tolerance=1e-9)


def test_a_steady_temperature_of_a_vessel_whose_states_are_mass_and_energy(tmp_path):
    # der(T) = (der(U) - c T der(m))/(m c) = 0  =>  w c Tin + Q = c T w  =>  T = Tin + Q/(c w) = 400, and
    # it stays there: U = m c T = 1600 m, m = w/k + (m0 - w/k) exp(-k t) = 4 + 6 exp(-t/2)
    out = _run(tmp_path, VESSEL, "SteadyT", ["m", "U", "T"])
    m = 4 + 6 * np.exp(-0.5 * out["time"])
    assert abs(out["T"][0] - 400.0) < 1e-9 and abs(out["U"][0] - 16000.0) < 1e-6
    assert np.allclose(out["m"], m, rtol=1e-6)
    assert np.allclose(out["T"], 400.0, rtol=1e-6) and np.allclose(out["U"], 1600 * m, rtol=1e-6)


DRIFT = """model Drift "y = x + time, steady at the start"
  parameter Real a = 2;
  parameter Real b = 3;
  Real x(start = 0);
  Real y;
initial equation
  der(y) = 0;
equation
  der(x) = -a*x + b;
  y = x + time;
end Drift;
"""


def test_a_variable_that_depends_on_time(tmp_path):
    # der(y) = der(x) + 1 = 0  =>  -a x0 + b = -1  =>  x0 = (b + 1)/a = 2; x = b/a + (x0 - b/a) exp(-a t)
    out = _run(tmp_path, DRIFT, "Drift", ["x", "y"])
    x = 1.5 + 0.5 * np.exp(-2 * out["time"])
    assert abs(out["x"][0] - 2.0) < 1e-9 and abs(out["y"][0] - 2.0) < 1e-9
    assert np.allclose(out["x"], x, rtol=1e-6) and np.allclose(out["y"], x + out["time"], rtol=1e-6)


LOOP = """model SteadyLoop "specific energy c T + e T^2: T the solution of an algebraic loop"
  parameter Real c = 4;
  parameter Real e = 0.001;
  parameter Real w = 2;
  parameter Real Tin = 300;
  parameter Real Q = 800;
  parameter Real k = 0.5;
  Real m(start = 10, fixed = true);
  Real U(start = 1000);
  Real T(start = 350);
initial equation
  der(T) = 0;
equation
  der(m) = w - k*m;
  der(U) = w*(c*Tin + e*Tin^2) - k*U + Q;
  U = m*(c*T + e*T^2);
end SteadyLoop;
"""


@pytest.mark.parametrize("u_start", ["start = 1000", "no start value: solved with the model's equations"])
def test_a_variable_given_by_an_algebraic_loop(tmp_path, u_start):
    # with u = U/m = c T + e T^2: der(u) = (der(U) - u der(m))/m = (w u(Tin) + Q - w u)/m = 0
    # => u = u(Tin) + Q/w = 1690, T the positive root of e T^2 + c T - u, U = m u (steady thereafter).
    # Without a start value U starts at 0 in a nonlinear block: the initial equations are solved with the
    # model's equations, from T's start value (.flat_systems._whole_initial_solution)
    text = LOOP if u_start.startswith("start") else LOOP.replace("Real U(start = 1000);", "Real U;")
    out = _run(tmp_path, text, "SteadyLoop", ["m", "U", "T"])
    u = 4 * 300 + 0.001 * 300**2 + 800 / 2
    t0 = (-4 + math.sqrt(16 + 4 * 0.001 * u)) / (2 * 0.001)
    m = 4 + 6 * np.exp(-0.5 * out["time"])
    assert abs(out["T"][0] - t0) < 1e-7 and abs(out["U"][0] - 10 * u) < 1e-6
    assert np.allclose(out["U"], u * m, rtol=1e-6) and np.allclose(out["T"], t0, rtol=1e-6)


INPUT = """model WithInput
  input Real u;
  Real x(start = 0);
  Real y;
initial equation
  der(y) = 0;
equation
  der(x) = -x + 1;
  y = x + u;
end WithInput;
"""


SECOND = """model Second
  Real x(start = 0);
  Real y;
initial equation
  der(y) = 0;
equation
  der(x) = -x + 1;
  y = der(x);
end Second;
"""


@pytest.mark.parametrize("name, text, match", [
    ("WithInput", INPUT, r"der\(y\) in an initial equation, where y is not a state and y depends on the input "
                         r"u.* at .*WithInput\.mo:6"),
    ("Second", SECOND, r"der\(y\) in an initial equation, where y is not a state and y depends on der\(x\).* "
                       r"at .*Second\.mo:5"),
])
def test_a_variable_on_an_input_or_a_derivative_is_refused_naming_the_equation(name, text, match, tmp_path):
    src = tmp_path / f"{name}.mo"
    src.write_text(text)
    with pytest.raises(UnsupportedConstructError, match=match):
        compile_model(src, name, backend="embedded", output=tmp_path / "out.fmu")
    assert not (tmp_path / "out.fmu").exists()
