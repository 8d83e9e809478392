"""Runtime semantics of embedded-path FMUs: asserts and initial equations.

Expectations are hand-computed: the steady state of a tank with a PI level
controller solved on paper, the time at which ``x = t`` crosses an assert's
bound, and the parameter an initial equation determines.
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from trackingbox.cli import main
from trackingbox.compiler import compile_model
from trackingbox.errors import AssertionFailed, CompileError, SimulationError
from trackingbox.fmu import FMUModel

pytestmark = pytest.mark.compile


def build(tmp_path: Path, name: str, text: str) -> Path:
    src = tmp_path / f"{name}.mo"
    src.write_text(text)
    return compile_model(src, name, backend="embedded", output=tmp_path / f"{name}.fmu").fmu


# ---------------------------------------------------------------------------
# initial equations: a tank with a PI controller on its outflow valve
# ---------------------------------------------------------------------------

TANK = """
model TankPI "Tank level h held at hSet by a PI controller on the outflow valve"
  parameter Real A = 2 "Tank cross-section (m2)";
  parameter Real Cv = 0.4 "Valve coefficient (m2.5/s)";
  parameter Real hSet = 1.5 "Level set-point (m)";
  parameter Real Kp = 2 "Controller gain (1/m)";
  parameter Real Ti = 10 "Integral time (s)";
  input Real qIn(start = 0.5) "Inflow (m3/s)";
  Real h(start = 0.2) "Level (m), a guess for the initialisation";
  Real I(start = 0) "Integral of the control error (m.s)";
  Real u "Valve opening";
  output Real qOut "Outflow (m3/s)";
equation
  A*der(h) = qIn - qOut;
  qOut = Cv*u*sqrt(h);
  u = Kp*((h - hSet) + I/Ti);
  der(I) = h - hSet;
initial equation
  der(h) = 0;
  der(I) = 0;
end TankPI;
"""


def tank_steady_state(qIn: float, Cv: float, hSet: float, Kp: float, Ti: float) -> tuple[float, float, float]:
    """By hand: der(I) = 0 gives h = hSet; der(h) = 0 gives Cv*u*sqrt(hSet) = qIn, and u = Kp*I/Ti."""
    u = qIn / (Cv * math.sqrt(hSet))
    return hSet, Ti * u / Kp, u


@pytest.fixture(scope="module")
def tank_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build(tmp_path_factory.mktemp("tank"), "TankPI", TANK)


def test_tank_starts_and_stays_at_hand_solved_steady_state(tank_fmu):
    assert validate_fmu(str(tank_fmu)) == []
    h0, i0, u0 = tank_steady_state(0.5, 0.4, 1.5, 2, 10)
    names = ["h", "I", "u", "der(h)", "der(I)"]
    with FMUModel(tank_fmu, tolerance=1e-10) as model:
        df = model.simulate(stop_time=200, output_interval=10, parameters={"qIn": 0.5}, outputs=names)
    first = df.iloc[0]
    assert abs(first["der(h)"]) < 1e-8 and abs(first["der(I)"]) < 1e-8
    assert np.isclose(first["h"], h0, rtol=1e-9) and np.isclose(first["I"], i0, rtol=1e-9)
    assert np.isclose(first["u"], u0, rtol=1e-9)
    # constant inflow: it stays there over the run
    assert np.allclose(df["h"], h0, rtol=1e-7) and np.allclose(df["I"], i0, rtol=1e-7)
    assert np.abs(df[["der(h)", "der(I)"]].to_numpy()).max() < 1e-8


def test_tank_steady_state_moves_with_parameters_set_before_initialisation(tank_fmu):
    h0, i0, _ = tank_steady_state(0.8, 0.3, 2.0, 2, 10)
    with FMUModel(tank_fmu, tolerance=1e-10) as model:
        df = model.simulate(stop_time=50, output_interval=10, parameters={"qIn": 0.8, "hSet": 2.0, "Cv": 0.3},
                            outputs=["h", "I", "der(h)", "der(I)"])
        # a later run with the defaults goes back to the first steady state (nothing kept from the last run)
        back = model.simulate(stop_time=10, output_interval=10, parameters={"qIn": 0.5}, outputs=["h", "I"])
    assert np.isclose(df["h"].iloc[0], h0, rtol=1e-9) and np.isclose(df["I"].iloc[0], i0, rtol=1e-9)
    assert abs(df["der(h)"].iloc[0]) < 1e-8 and abs(df["der(I)"].iloc[0]) < 1e-8
    assert np.allclose(df["h"], h0, rtol=1e-7)
    h1, i1, _ = tank_steady_state(0.5, 0.4, 1.5, 2, 10)
    assert np.isclose(back["h"].iloc[0], h1, rtol=1e-9) and np.isclose(back["I"].iloc[0], i1, rtol=1e-9)


def test_states_with_initial_equations_are_initial_unknowns(tank_fmu):
    with FMUModel(tank_fmu) as model:
        h = model.info.variable("h")
    assert h.causality == "local"
    from fmpy import read_model_description

    md = read_model_description(str(tank_fmu))
    initial = {u.variable.name for u in md.initialUnknowns}
    assert {"h", "I"} <= initial


HEATER = """
model Heater "A heated room whose heat-transfer coefficient UA follows from a measured steady temperature"
  parameter Real C = 5e5 "Heat capacity (J/K)";
  parameter Real P = 2000 "Heating power (W)";
  parameter Real Ta = 5 "Ambient temperature (degC)";
  parameter Real Tmeas = 21 "Measured steady room temperature (degC)";
  parameter Real UA(fixed = false, start = 50) "Heat-transfer coefficient (W/K), from the initial equations";
  Real T(start = 15) "Room temperature (degC)";
equation
  C*der(T) = P - UA*(T - Ta);
initial equation
  der(T) = 0;
  T = Tmeas;
end Heater;
"""


def test_fixed_false_parameter_is_determined_by_initial_equations(tmp_path):
    src = tmp_path / "Heater.mo"
    src.write_text(HEATER)
    result = compile_model(src, "Heater", backend="embedded", output=tmp_path / "Heater.fmu")
    fmu = result.fmu
    # C, P, Ta, Tmeas can be tuned; UA is computed at initialisation, not a tunable parameter
    assert result.parameters == 4
    assert "4 tunable parameters and 1 computed at initialisation" in result.log
    assert validate_fmu(str(fmu)) == []
    with FMUModel(fmu) as model:
        assert model.info.variable("UA").causality == "calculatedParameter"
        assert "UA" not in model.info.tunable_parameters
        df = model.simulate(stop_time=3600, output_interval=600, outputs=["T", "UA", "der(T)"])
        df2 = model.simulate(stop_time=600, output_interval=600, parameters={"P": 3000.0}, outputs=["T", "UA"])
    # by hand: at steady state P = UA*(Tmeas - Ta)
    assert np.allclose(df["UA"], 2000 / (21 - 5), rtol=1e-10)
    assert np.allclose(df["T"], 21, rtol=1e-9)
    assert abs(df["der(T)"].iloc[0]) < 1e-10
    assert np.allclose(df2["UA"], 3000 / (21 - 5), rtol=1e-10)


def test_fixed_false_parameter_cannot_be_set(tmp_path):
    fmu = build(tmp_path, "Heater", HEATER)
    from trackingbox.errors import FMUError

    with FMUModel(fmu) as model, pytest.raises(FMUError, match="UA"):
        model.simulate(stop_time=10, output_interval=10, parameters={"UA": 100.0})


def test_initial_equations_without_a_solution_fail_with_a_clear_error(tmp_path):
    text = """
model NoRoot
  parameter Real c = 1;
  Real x(start = 1);
equation
  der(x) = x*x + c;
initial equation
  der(x) = 0;
end NoRoot;
"""
    fmu = build(tmp_path, "NoRoot", text)  # x^2 + 1 = 0 has no real root
    with FMUModel(fmu) as model, pytest.raises(SimulationError, match="initialisation .*initial equation"):
        model.simulate(stop_time=1, output_interval=1)
    with FMUModel(fmu) as model:  # with c = -4 the root x = 2 is found from the start value 1
        df = model.simulate(stop_time=1, output_interval=1, parameters={"c": -4.0}, outputs=["x"])
    assert np.isclose(df["x"].iloc[0], 2.0, rtol=1e-10)


def test_unbalanced_initial_equations_are_refused_naming_the_counts(tmp_path):
    text = """
model TooMany
  Real x(start = 1, fixed = true);
equation
  der(x) = -x;
initial equation
  der(x) = 0;
end TooMany;
"""
    with pytest.raises(CompileError, match=r"1 equations for 0 unknowns"):
        build(tmp_path, "TooMany", text)


def test_state_without_initial_equation_keeps_its_start_value(tmp_path):
    text = """
model Two
  parameter Real a = 2;
  Real x(start = 3);
  Real y(start = 0.25);
equation
  der(x) = a - x;
  der(y) = -y;
initial equation
  der(x) = 0;
end Two;
"""
    fmu = build(tmp_path, "Two", text)
    with FMUModel(fmu, tolerance=1e-10) as model:
        df = model.simulate(stop_time=1, output_interval=1, outputs=["x", "y"])
    assert np.isclose(df["x"].iloc[0], 2.0) and np.isclose(df["y"].iloc[0], 0.25)
    assert np.isclose(df["y"].iloc[1], 0.25 * math.exp(-1), rtol=1e-6)


# ---------------------------------------------------------------------------
# asserts
# ---------------------------------------------------------------------------

RAMP = """
model Ramp "x = t"
  parameter Real k = 1;
  Real x(start = 0, fixed = true);
equation
  der(x) = 1;
  assert(x < 2, "x too large");
  assert(k > 0, "k must be positive: \\"k\\" in 1/°C, 100% sure");
  assert(x < 1, "x above one", AssertionLevel.warning);
end Ramp;
"""


@pytest.fixture(scope="module")
def ramp_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build(tmp_path_factory.mktemp("ramp"), "Ramp", RAMP)


def test_failing_assert_stops_the_simulation_with_message_and_time(ramp_fmu):
    with FMUModel(ramp_fmu) as model, pytest.raises(AssertionFailed) as exc:
        model.simulate(stop_time=3, output_interval=0.01, outputs=["x"])
    assert isinstance(exc.value, SimulationError)
    assert exc.value.message == "x too large"
    assert 2.0 <= exc.value.time <= 2.01 + 1e-9  # x = t reaches 2 at t = 2; checked every 0.01 s


def test_warning_assert_logs_and_the_run_finishes(ramp_fmu, caplog):
    with caplog.at_level(logging.WARNING, logger="trackingbox.fmu"), FMUModel(ramp_fmu) as model:
        df = model.simulate(stop_time=1.5, output_interval=0.1, outputs=["x"])
    assert np.isclose(df["x"].iloc[-1], 1.5)
    warnings = [r.getMessage() for r in caplog.records if "x above one" in r.getMessage()]
    assert len(warnings) == 1 and "t = 1 s" in warnings[0]


def test_parameter_assert_is_checked_at_initialisation_and_after_a_change(ramp_fmu):
    with FMUModel(ramp_fmu) as model:
        with pytest.raises(AssertionFailed, match="k must be positive") as exc:
            model.simulate(stop_time=1, output_interval=0.1, parameters={"k": -1.0})
        assert exc.value.time == 0.0
        assert exc.value.message == 'k must be positive: "k" in 1/°C, 100% sure'  # quotes, UTF-8, % kept
        stepper = model.stepper(start_time=0.0)
        stepper.step(0.5)
        with pytest.raises(AssertionFailed, match="k must be positive") as exc:
            stepper.set({"k": -2.0})
        assert exc.value.time == 0.5


def test_cli_simulate_prints_one_error_line_and_fails(ramp_fmu, tmp_path, capsys):
    out = tmp_path / "r.csv"
    code = main(["simulate", str(ramp_fmu), "-o", str(out), "--stop", "3", "--step", "0.01"])
    err = capsys.readouterr().err
    errors = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert code != 0
    assert len(errors) == 1 and "x too large" in errors[0] and "t = 2" in errors[0]
    assert "Traceback" not in err and not out.exists()


FUNCTION_ASSERT = """
model FunctionAssert
  function checked "2u; asserts u < 3, and u < 1 only where u > 5"
    input Real u;
    output Real y;
  algorithm
    assert(u < 3, "u too large in checked");
    if u > 5 then
      assert(u < 1, "never reached before t = 5");
    end if;
    y := 2*u;
  end checked;
  output Real y;
equation
  y = checked(time);
end FunctionAssert;
"""


def test_assert_in_an_inlined_function(tmp_path):
    fmu = build(tmp_path, "FunctionAssert", FUNCTION_ASSERT)
    with FMUModel(fmu) as model:
        df = model.simulate(stop_time=2.5, output_interval=0.5, outputs=["y"])
        assert np.allclose(df["y"], 2 * df["time"])  # the assert inside the if-branch does not fire
        with pytest.raises(AssertionFailed, match="u too large in checked") as exc:
            model.simulate(stop_time=4, output_interval=0.5)
    assert exc.value.time == 3.0


def test_assert_conditions_are_outputs_of_the_model_function(ramp_fmu):
    """The conditions are computed by the model's own evaluation (``_tbx_a<k>``, 1 where the assert
    holds), not by a second function in the runtime; by hand at x = t: x < 2 and k > 0 hold up to
    t = 1.5, x < 1 (the warning) only before t = 1."""
    import zipfile

    with zipfile.ZipFile(ramp_fmu) as zf:
        runtime = zf.read("sources/tbx_runtime.c").decode()
    assert "tbx_asserts" not in runtime and "_tbx_a1" not in runtime
    with FMUModel(ramp_fmu) as model:
        df = model.simulate(stop_time=1.5, output_interval=0.5, outputs=["_tbx_a1", "_tbx_a2", "_tbx_a3"])
    assert list(df["_tbx_a1"]) == [1.0, 1.0, 1.0, 1.0]
    assert list(df["_tbx_a2"]) == [1.0, 1.0, 1.0, 1.0]
    assert list(df["_tbx_a3"]) == [1.0, 1.0, 0.0, 0.0]  # x = 1 at t = 1: x < 1 fails there


TWO_CALLS = """
model TwoCalls
  function checked "2u; asserts u < 3"
    input Real u;
    output Real y;
  algorithm
    assert(u < 3, "u too large in checked");
    y := 2*u;
  end checked;
  output Real y1;
  output Real y2;
equation
  y1 = checked(time);
  y2 = checked(2*time);
end TwoCalls;
"""


def test_asserts_with_one_message_are_one_condition_of_the_fmu(tmp_path):
    """The two calls' asserts (one message) are one output, holding where both hold: by hand the second
    call's u = 2t reaches 3 at t = 1.5, the first call's only at t = 3."""
    import zipfile

    fmu = build(tmp_path, "TwoCalls", TWO_CALLS)
    with zipfile.ZipFile(fmu) as zf:
        xml = zf.read("modelDescription.xml").decode()
    assert 'name="_tbx_a1"' in xml and 'name="_tbx_a2"' not in xml
    with FMUModel(fmu) as model:
        df = model.simulate(stop_time=1.25, output_interval=0.25, outputs=["_tbx_a1", "y2"])
        assert list(df["_tbx_a1"]) == [1.0] * 6 and np.allclose(df["y2"], 4 * df["time"])
        with pytest.raises(AssertionFailed, match="u too large in checked") as exc:
            model.simulate(stop_time=2, output_interval=0.25)
    assert exc.value.time == 1.5


@pytest.mark.parametrize("construct", ["initial", "terminal"])
def test_initial_and_terminal_in_an_assert(tmp_path, construct):
    """initial() is true only during initialisation, terminal() never during a run: the assert fails
    where x falls below 0.5, at t = ln 2."""
    text = f"""
model UsesIt
  Real x(start = 1, fixed = true);
equation
  der(x) = -x;
  assert({construct}() or x > 0.5, "x above 0.5");
end UsesIt;
"""
    fmu = build(tmp_path, "UsesIt", text)
    with FMUModel(fmu) as model, pytest.raises(AssertionFailed, match="x above 0.5") as exc:
        model.simulate(stop_time=2, output_interval=0.05)
    assert abs(exc.value.time - math.log(2)) <= 0.05


@pytest.mark.parametrize("start,stops", [(1.0, False), (0.25, True)])
def test_an_if_equation_on_initial_of_asserts_is_checked_at_initialisation_only(tmp_path, start, stops):
    """rumoca 0.10.2 drops `if initial() then assert(...); end if;` (refused before): the assert is
    read outside it with initial() in its guard. x = x0*exp(-t) falls below 0.5 at t = ln 2 when
    x0 = 1 (after initialisation: the run goes on), and is below it at t = 0 when x0 = 0.25."""
    text = f"""
model UsesIt
  Real x(start = {start}, fixed = true);
equation
  der(x) = -x;
  if initial() then
    assert(x > 0.5, "x above 0.5 at initialisation");
  end if;
end UsesIt;
"""
    fmu = build(tmp_path, "UsesIt", text)
    with FMUModel(fmu) as model:
        if stops:
            with pytest.raises(AssertionFailed, match="x above 0.5 at initialisation") as exc:
                model.simulate(stop_time=2, output_interval=0.05)
            assert exc.value.time == 0.0
        else:
            df = model.simulate(stop_time=2, output_interval=0.05, outputs=["x"])
            assert np.isclose(df["x"].iloc[-1], math.exp(-2), rtol=1e-3)


def test_models_without_asserts_or_initial_equations_get_no_runtime(tmp_path):
    text = """
model Plain
  Real x(start = 1, fixed = true);
equation
  der(x) = -x;
end Plain;
"""
    import zipfile

    fmu = build(tmp_path, "Plain", text)
    with zipfile.ZipFile(fmu) as zf:
        names = zf.namelist()
        wrapper = zf.read("sources/Plain_wrap.c").decode()
    assert "sources/tbx_runtime.c" not in names and "tbx_" not in wrapper
    with zipfile.ZipFile(build(tmp_path, "Ramp", RAMP)) as zf:
        assert "sources/tbx_runtime.c" in zf.namelist()


DRAIN = """
model Drain "empties at t* = 2 (1 - ln 2); beyond it sqrt(h) has no value and the solver fails"
  Real h(start = 1, fixed = true);
equation
  der(h) = -sqrt(h) - 1;
  assert(h > 0, "tank empty");
end Drain;
"""


def test_assert_failing_inside_a_step_the_solver_cannot_finish_is_reported(tmp_path):
    fmu = build(tmp_path, "Drain", DRAIN)
    t_empty = 2 * (1 - math.log(2))  # by hand: s = sqrt(h), 2 s ds/dt = -(s + 1), t* = int_0^1 2s/(s+1) ds
    with FMUModel(fmu) as model, pytest.raises(AssertionFailed) as exc:
        model.simulate(stop_time=20, output_interval=10)  # the assert fails long before the first point
    assert exc.value.message == "tank empty"
    assert abs(exc.value.time - t_empty) <= 0.05  # a trial point of the failed step


LEVEL_TANK = """
model Tank "the level is not a state: level(fixed = true) is an initial equation for the mass"
  parameter Real rho = 1000;
  parameter Real A = 2;
  parameter Real k = 500;
  parameter Real cp = 4;
  parameter Real T0 = 300;
  Real m "state: mass";
  Real H "state: enthalpy";
  Real level(start = 0.9, fixed = true);
  Real T;
initial equation
  T = T0;
equation
  m = rho*A*level;
  der(m) = -k*level;
  H = m*cp*T;
  der(H) = -k*level*cp*T;
end Tank;
"""


def test_fixed_start_of_an_algebraic_variable_is_an_initial_equation(tmp_path):
    """level(fixed = true) sets the state m through m = rho A level; the initial equations are solved
    one block at a time, m before T = H/(m cp), so the start value m = 0 divides by nothing."""
    fmu = build(tmp_path, "Tank", LEVEL_TANK)
    with FMUModel(fmu, tolerance=1e-10) as model:
        df = model.simulate(stop_time=4, output_interval=1, outputs=["level", "T", "m"])
    assert np.allclose(df["level"], 0.9 * np.exp(-500 * df["time"] / 2000), rtol=1e-6)
    assert np.allclose(df["T"], 300.0, rtol=1e-8)
    assert np.allclose(df["m"], 2000 * df["level"], rtol=1e-9)


FIXED_START = """
model Decay
  Real x;
  Real v(start = 0, fixed = true) "not the state: its start value is an initial equation";
equation
  v = 2*x;
  der(x) = -x;
end Decay;
"""


def test_the_initial_solve_writes_every_element_of_its_outputs(tmp_path):
    """The initial equation 2 x = v.start = 0, solved as x = 0, has a residual that is structurally zero; the
    generated C writes only an output's structural nonzeros, and the runtime reads every element (before,
    an uninitialised residual on the stack failed the MSL's OpAmps.Integrator with 'residual 1 of the start
    value of integrator.v'). Called with outputs filled with NaN, tbx_init gives the state x = 0 and the residual 0."""
    import ctypes
    import zipfile

    fmu = build(tmp_path, "Decay", FIXED_START)
    with zipfile.ZipFile(fmu) as z:
        z.extractall(tmp_path / "x")
    lib = ctypes.CDLL(str(next((tmp_path / "x" / "binaries").glob("*/*.so"))))
    sizes = [ctypes.c_longlong() for _ in range(4)]
    assert lib.tbx_init_work(*(ctypes.byref(s) for s in sizes)) == 0
    n_arg, n_res, n_iw, n_w = (max(s.value, 1) for s in sizes)
    z0, wk = (ctypes.c_double * 2)(0.5, 0.0), (ctypes.c_double * 1)(0.0)
    z, r = (ctypes.c_double * 1)(math.nan), (ctypes.c_double * 1)(math.nan)
    arg = (ctypes.POINTER(ctypes.c_double) * n_arg)(ctypes.cast(z0, ctypes.POINTER(ctypes.c_double)),
                                                    ctypes.cast(wk, ctypes.POINTER(ctypes.c_double)))
    res = (ctypes.POINTER(ctypes.c_double) * n_res)(ctypes.cast(z, ctypes.POINTER(ctypes.c_double)),
                                                    ctypes.cast(r, ctypes.POINTER(ctypes.c_double)))
    iw, w = (ctypes.c_longlong * n_iw)(), (ctypes.c_double * n_w)()
    assert lib.tbx_init(arg, res, iw, w, 0) == 0
    assert z[0] == 0.0
    assert r[0] == 0.0
