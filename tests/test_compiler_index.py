"""Index reduction in the embedded compiler (issue 35, item 2): Pantelides' algorithm and the choice
of states, on higher-index models with closed-form solutions, and its limits."""
from __future__ import annotations

import math

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import CompileError

pytestmark = pytest.mark.compile

MODELS = """
package Idx
  model Coupled "two masses joined rigidly on one spring: one oscillator of mass m1 + m2"
    parameter Real m1 = 1;
    parameter Real m2 = 3;
    parameter Real k = 16;
    Real x1(start = 0.5, fixed = true);
    Real v1(start = 0, fixed = true);
    Real x2(start = 0.5);
    Real v2;
    Real f "force of mass 1 on mass 2";
  equation
    der(x1) = v1;
    m1*der(v1) = -k*x1 - f;
    der(x2) = v2;
    m2*der(v2) = f;
    x1 = x2;
  end Coupled;
  model Prescribed "a mass moved along x = sin(w t): the force it needs, f = -m w^2 sin(w t)"
    parameter Real m = 2;
    parameter Real w = 3;
    Real x;
    Real v;
    Real f;
  equation
    x = sin(w*time);
    der(x) = v;
    m*der(v) = f;
  end Prescribed;
  model Capacitors "two capacitors in parallel discharging through a resistor"
    parameter Real C1 = 1e-3;
    parameter Real C2 = 3e-3;
    parameter Real R = 100;
    Real v1(start = 10, fixed = true);
    Real v2(stateSelect = StateSelect.avoid);
    Real i1;
    Real i2;
  equation
    C1*der(v1) = i1;
    C2*der(v2) = i2;
    v1 = v2;
    i1 + i2 = -v1/R;
  end Capacitors;
  model Preferred "the same, with v2 preferred as the state"
    extends Capacitors(v2(stateSelect = StateSelect.prefer, start = 10, fixed = true), v1(fixed = false));
  end Preferred;
  model FromInput "a mass moved by an input position: the input's derivatives would be needed"
    input Real u;
    Real x;
    Real v;
    Real f;
  equation
    x = u;
    der(x) = v;
    2*der(v) = f;
  end FromInput;
end Idx;
"""


@pytest.fixture(scope="module")
def idx(tmp_path_factory):
    src = tmp_path_factory.mktemp("idx") / "Idx.mo"
    src.write_text(MODELS)
    return src


def run(idx, tmp_path, name, stop, names):
    res = compile_model(idx, f"Idx.{name}", backend="embedded", output=tmp_path / f"{name}.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=stop, output_interval=stop / 50, output=names,
                            relative_tolerance=1e-10)
    return res, out


def test_rigidly_coupled_masses_move_as_one(idx, tmp_path):
    res, out = run(idx, tmp_path, "Coupled", 3.0, ["x1", "x2", "f"])
    w = math.sqrt(16 / 4)
    t = out["time"]
    assert res.states == 2  # x1 and v1 (x2, v2 follow from the constraint)
    assert np.allclose(out["x1"], 0.5 * np.cos(w * t), atol=1e-7)
    assert np.allclose(out["x2"], out["x1"], atol=1e-12)
    assert np.allclose(out["f"], 3 * (-0.5 * w ** 2 * np.cos(w * t)), atol=1e-5)  # m2 * a


def test_a_prescribed_motion_gives_its_force(idx, tmp_path):
    res, out = run(idx, tmp_path, "Prescribed", 2.0, ["x", "v", "f"])
    t = out["time"]
    assert res.states == 0
    assert np.allclose(out["v"], 3 * np.cos(3 * t), atol=1e-9)
    assert np.allclose(out["f"], -2 * 9 * np.sin(3 * t), atol=1e-8)


def test_parallel_capacitors_discharge_with_the_sum_of_capacities(idx, tmp_path):
    tau = 100 * 4e-3
    for name in ("Capacitors", "Preferred"):
        res, out = run(idx, tmp_path, name, 1.0, ["v1", "v2", "i1"])
        t = out["time"]
        assert res.states == 1
        assert np.allclose(out["v1"], 10 * np.exp(-t / tau), rtol=1e-7)
        assert np.allclose(out["v2"], out["v1"], rtol=1e-12)
        assert np.allclose(out["i1"], 1e-3 * -10 / tau * np.exp(-t / tau), rtol=1e-6)
        states = [d.variable.name for d in fmpy.read_model_description(str(res.fmu)).derivatives]
        assert states == (["der(v1)"] if name == "Capacitors" else ["der(v2)"])  # stateSelect decides


def test_a_model_that_would_differentiate_an_input_is_refused(idx, tmp_path):
    with pytest.raises(CompileError, match="structurally singular"):
        compile_model(idx, "Idx.FromInput", backend="embedded", output=tmp_path / "f.fmu")
