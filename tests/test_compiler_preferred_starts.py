"""Free states started from the variables a model prefers as states (issue 35): a tool picks its
states by ``stateSelect`` and starts a state no initial equation fixes at its start value; the embedded
compiler keeps the differentiated variables as states, so it starts them where the preferred
variables are at their start values (as the Fluid vessels need: ``U`` and ``m`` are differentiated,
``level`` and the medium's ``T`` are preferred). The expectations are worked by hand."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

MODELS = """
package Pref
  model Level "a tank filled at q: its mass is differentiated, its level preferred as the state"
    parameter Real A = 2;
    parameter Real rho = 1000;
    parameter Real q = 10;
    Real m(start = 7) "mass";
    Real level(stateSelect = StateSelect.prefer, start = 0.8);
  equation
    der(m) = q;
    m = rho*A*level;
  end Level;
  model Fixed "the same with an initial equation for the mass: the level's start is not used"
    extends Level;
  initial equation
    m = 500;
  end Fixed;
  model Heated "mass and internal energy balanced; temperature and level preferred, the pressure
    preferred too but set by a parameter (its start value is not used)"
    parameter Real A = 2;
    parameter Real V0 = 0.1;
    parameter Real rho = 1000;
    parameter Real cp = 4000;
    parameter Real T0 = 273.15;
    parameter Real q = 10;
    parameter Real T_in = 350;
    parameter Real p_ambient = 1e5;
    Real T(stateSelect = StateSelect.prefer, start = 300);
    Real m;
    Real U;
    Real p(stateSelect = StateSelect.prefer, start = 2e5);
    Real level(stateSelect = StateSelect.prefer, start = 0.5);
  equation
    der(m) = q;
    der(U) = q*cp*(T_in - T0);
    m = rho*(A*level + V0);
    U = m*cp*(T - T0);
    p = p_ambient;
  end Heated;
  model Avoided "a variable with stateSelect = avoid does not stand in for the free state"
    Real x(start = 3);
    Real y(stateSelect = StateSelect.avoid, start = 10);
  equation
    der(x) = -x;
    y = 2*x;
  end Avoided;
  model Through "an initial equation on an algebraic variable that depends on the first state only"
    Real x1(start = 4);
    Real x2(start = 7);
    Real a;
  equation
    der(x1) = -x1;
    der(x2) = -2*x2;
    a = 2*x1;
  initial equation
    a = 1;
  end Through;
end Pref;
"""


@pytest.fixture(scope="module")
def src(tmp_path_factory):
    path = tmp_path_factory.mktemp("pref") / "Pref.mo"
    path.write_text(MODELS)
    return path


def run(src, tmp_path, name, stop, names):
    res = compile_model(src, f"Pref.{name}", backend="embedded", output=tmp_path / f"{name}.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=stop, output_interval=stop / 20, output=names,
                            relative_tolerance=1e-10, fmi_type="ModelExchange")
    return res, out


def test_a_preferred_level_sets_the_free_mass(src, tmp_path):
    res, out = run(src, tmp_path, "Level", 2.0, ["m", "level"])
    assert res.states == 1
    t = out["time"]
    assert np.allclose(out["m"], 1000 * 2 * 0.8 + 10 * t, rtol=1e-12)  # m(0) = rho*A*level_start, not 7
    assert out["level"][0] == pytest.approx(0.8, rel=1e-14)


def test_an_initial_equation_wins_over_a_preferred_start(src, tmp_path):
    _, out = run(src, tmp_path, "Fixed", 2.0, ["m", "level"])
    assert np.allclose(out["m"], 500 + 10 * out["time"], rtol=1e-12)
    assert out["level"][0] == pytest.approx(500 / 2000, rel=1e-14)


def test_temperature_and_level_set_mass_and_energy(src, tmp_path):
    res, out = run(src, tmp_path, "Heated", 20.0, ["m", "U", "T", "level", "p"])
    assert res.states == 2
    t = out["time"]
    m0 = 1000 * (2 * 0.5 + 0.1)  # 1100 kg from level_start
    assert np.allclose(out["m"], m0 + 10 * t, rtol=1e-12)
    # energy: U = m cp (T - T0), d U/dt = q cp (T_in - T0) from U(0) = m0 cp (300 - T0)
    expected_t = 273.15 + (m0 * (300 - 273.15) + 10 * t * (350 - 273.15)) / (m0 + 10 * t)
    assert np.allclose(out["T"], expected_t, rtol=1e-11)
    assert np.allclose(out["p"], 1e5)  # its start, 2e5, determines nothing


def test_an_avoided_variable_leaves_the_state_at_its_own_start(src, tmp_path):
    _, out = run(src, tmp_path, "Avoided", 1.0, ["x", "y"])
    assert np.allclose(out["x"], 3 * np.exp(-out["time"]), rtol=1e-8)


def test_a_state_determined_through_an_algebraic_variable_is_not_the_one_kept_at_its_start(src, tmp_path):
    """One initial equation for two free states, named by none: x1, the first, was kept at its start
    and a = 2*x1 = 1 left with no unknown (refused as structurally singular); x1 is determined (0.5)
    and x2 keeps its start, 7."""
    _, out = run(src, tmp_path, "Through", 1.0, ["x1", "x2"])
    t = out["time"]
    assert np.allclose(out["x1"], 0.5 * np.exp(-t), rtol=1e-8)
    assert np.allclose(out["x2"], 7 * np.exp(-2 * t), rtol=1e-8)
