"""FMU layer: read_info, FMUModel, Stepper against the hand-solved first-order lag.

dx/dt = k (u - x)  =>  x(t) = u + (x(t0) - u) exp(-k (t - t0)) for constant u, k.
Four FMUs implement it (see _fixtures_fmu): FMI 3.0 ME (CasADi), FMI 2.0 ME
(hand-written C), FMI 2.0 CS (pythonfmu) and FMI 3.0 CS (FMPy's C template), the
co-simulation ones with an exact per-step update.
"""
from __future__ import annotations

import gc
import re
import zipfile
from pathlib import Path

import fmpy
import fmpy.simulation
import numpy as np
import pandas as pd
import pytest
from _fixtures_fmu import cs2_fmu, cs3_fmu, me2_fmu, me3_fmu

from trackingbox.errors import DataError, FMUError, SimulationError
from trackingbox.fmu import FMUModel, read_info

FMUS = {"fmi3-me": me3_fmu, "fmi2-me": me2_fmu, "fmi2-cs": cs2_fmu, "fmi3-cs": cs3_fmu}
RTOL = 1e-4  # solver tolerance 1e-6; global error of CVODE stays well below this


def lag(t, x0, u, k, t0=0.0):
    """Hand solution of dx/dt = k (u - x) for constant u and k."""
    return u + (x0 - u) * np.exp(-k * (np.asarray(t) - t0))


@pytest.fixture(params=sorted(FMUS), scope="module")
def fmu_path(request) -> Path:
    return FMUS[request.param]()


@pytest.fixture(scope="module")
def model(fmu_path):
    with FMUModel(fmu_path) as m:
        yield m


# -- read_info -----------------------------------------------------------------

def test_read_info_fmi3_me():
    info = read_info(me3_fmu())
    assert info.fmi_version == "3.0"
    assert info.interfaces == ("ModelExchange",)
    k = info.variable("k")
    assert (k.causality, k.variability, k.start, k.min, k.max) == ("parameter", "tunable", 2.0, 0.5, 5.0)
    assert k.description == "rate constant"
    assert info.variable("u").causality == "input"
    assert info.outputs == ["y"] and info.inputs == ["u"]
    assert info.number_of_states == 1


def test_read_info_fmi2_units_come_from_declared_types():
    info = read_info(me2_fmu())
    assert info.fmi_version == "2.0"
    k, u = info.variable("k"), info.variable("u")
    assert (k.unit, k.min, k.max) == ("1/s", 0.0, 10.0)
    assert (u.unit, u.nominal, u.start) == ("K", 300.0, 1.0)
    assert info.stop_time == 3.0 and info.step_size == 0.1


def test_read_info_fmi2_cs():
    info = read_info(cs2_fmu())
    assert info.interfaces == ("CoSimulation",)
    assert info.variable("x0").variability == "fixed"
    assert info.tunable_parameters == ["k"]


def test_read_info_unknown_variable_suggests():
    with pytest.raises(FMUError, match=r"unknown variable 'kk'.*did you mean 'k'"):
        read_info(me3_fmu()).variable("kk")


def _corrupt(tmp_path: Path, kind: str) -> Path:
    path = tmp_path / f"{kind}.fmu"
    if kind == "not-zip":
        path.write_text("this is not an FMU\n")
    elif kind == "no-description":
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("binaries/linux64/x.so", b"\0")
    elif kind == "bad-xml":
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("modelDescription.xml", "<fmiModelDescription fmiVersion='2.0' <ModelVariables>")
    return path


@pytest.mark.parametrize("kind, problem", [
    ("missing", "does not exist"),
    ("not-zip", "not a ZIP archive"),
    ("no-description", "no modelDescription.xml"),
    ("bad-xml", "invalid modelDescription.xml"),
])
def test_read_info_bad_files_name_path_and_problem(tmp_path, kind, problem):
    path = tmp_path / "missing.fmu" if kind == "missing" else _corrupt(tmp_path, kind)
    with pytest.raises(FMUError) as exc:
        read_info(path)
    assert str(path) in str(exc.value) and problem in str(exc.value)
    assert "Traceback" not in str(exc.value)
    assert exc.value.__suppress_context__ or exc.value.__context__ is None
    with pytest.raises(FMUError, match=re.escape(problem)):
        FMUModel(path)


# -- simulate: analytic agreement ------------------------------------------------

def test_simulate_matches_hand_solution(model):
    df = model.simulate(stop_time=2.0, output_interval=0.25, parameters={"k": 3.0})
    assert list(df.columns) == ["time", *model.info.outputs]
    assert np.allclose(df["time"], np.arange(0, 2.0001, 0.25))
    assert np.allclose(df["y"], lag(df["time"], 0.5, 1.0, 3.0), rtol=RTOL)


def test_simulate_input_ramp_piecewise_hand_solution():
    # u = 1 until t = 0.5, then a ramp to 2 at t = 1, held at 2 afterwards; k = 2, x(0) = 0.5.
    # ramp u = 1 + b s (s = t - 0.5, b = 2): x = 1 + b s - b/k + C exp(-k s), C = x(0.5) - (1 - b/k)
    k, b = 2.0, 2.0
    x05 = lag(0.5, 0.5, 1.0, k)
    inputs = pd.DataFrame({"time": [0.0, 0.5, 1.0], "u": [1.0, 1.0, 2.0]})
    with FMUModel(me3_fmu()) as m:
        df = m.simulate(stop_time=2.0, output_interval=0.25, inputs=inputs)
    t = df["time"].to_numpy()
    s = t - 0.5
    ramp = 1 + b * s - b / k + (x05 - (1 - b / k)) * np.exp(-k * s)
    x1 = 1 + b * 0.5 - b / k + (x05 - (1 - b / k)) * np.exp(-k * 0.5)
    expected = np.where(t <= 0.5, lag(t, 0.5, 1.0, k), np.where(t <= 1.0, ramp, lag(t, x1, 2.0, k, 1.0)))
    assert np.allclose(df["y"], expected, rtol=RTOL)


def test_cs_holds_input_sample_over_step_and_sees_every_sample():
    # a step of u from 1 to 3 at t = 0.7 (between output points 0.5 and 1.0)
    inputs = pd.DataFrame({"time": [0.0, 0.7], "u": [1.0, 3.0]})
    with FMUModel(cs2_fmu()) as m:
        df = m.simulate(stop_time=1.5, output_interval=0.5, inputs=inputs, outputs=["y"])
    x07 = lag(0.7, 0.5, 1.0, 2.0)
    # on [0, 0.7) the CS FMU holds u(0) = 1 and u(0.5) = 1 + (3 - 1) * 0.5/0.7 over each step
    u05 = 1 + 2 * 0.5 / 0.7
    x05 = lag(0.5, 0.5, 1.0, 2.0)
    x07 = lag(0.7, x05, u05, 2.0, 0.5)
    assert np.isclose(df["y"].iloc[1], x05, rtol=1e-9)
    assert np.isclose(df["y"].iloc[2], lag(1.0, x07, 3.0, 2.0, 0.7), rtol=1e-9)


# -- Stepper -------------------------------------------------------------------------

def test_parameter_change_between_steps_follows_piecewise_solution(model):
    st = model.stepper()
    ys = []
    for t in np.arange(0.1, 1.0001, 0.1):
        st.step(t)
        ys.append(st.get(["y"])[0])
    st.set({"k": 0.5})
    for t in np.arange(1.1, 2.0001, 0.1):
        st.step(t)
        ys.append(st.get(["y"])[0])
    assert st.time == pytest.approx(2.0)
    t = np.arange(1, 21) * 0.1
    x1 = lag(1.0, 0.5, 1.0, 2.0)
    expected = np.where(t <= 1.0 + 1e-9, lag(t, 0.5, 1.0, 2.0), lag(t, x1, 1.0, 0.5, 1.0))
    assert np.allclose(ys, expected, rtol=RTOL)


def test_input_set_between_steps(model):
    st = model.stepper()
    st.step(1.0)
    st.set({"u": 3.0})
    st.step(2.0)
    x1 = lag(1.0, 0.5, 1.0, 2.0)
    assert st.get(["y"])[0] == pytest.approx(lag(2.0, x1, 3.0, 2.0, 1.0), rel=RTOL)


def test_set_rejects_unknown_and_non_tunable(model):
    st = model.stepper()
    with pytest.raises(FMUError, match=r"unknown variable 'kk'.*did you mean 'k'"):
        st.set({"kk": 1.0})
    with pytest.raises(FMUError, match="'y'.*only tunable parameters and inputs"):
        st.set({"y": 1.0})
    with pytest.raises(FMUError, match=r"unknown variable 'yy'.*did you mean 'y'"):
        st.get(["yy"])


def test_fixed_parameter_cannot_change_during_a_run():
    with FMUModel(cs2_fmu()) as m:
        st = m.stepper(parameters={"x0": 0.2})
        st.step(1.0)
        assert st.get(["y"])[0] == pytest.approx(lag(1.0, 0.2, 1.0, 2.0), rel=1e-9)
        with pytest.raises(FMUError, match="'x0'.*fixed parameter"):
            st.set({"x0": 0.3})


def test_checkpoint_and_resume_continuous_states():
    with FMUModel(me3_fmu()) as m:
        st = m.stepper(parameters={"k": 1.5})
        st.step(1.0)
        x1 = st.get_continuous_states()
        assert x1 == pytest.approx([lag(1.0, 0.5, 1.0, 1.5)], rel=RTOL)
        resumed = m.stepper(start_time=1.0, parameters={"k": 1.5})
        resumed.set_continuous_states(x1)
        resumed.step(2.0)
        assert resumed.get(["y"])[0] == pytest.approx(lag(2.0, 0.5, 1.0, 1.5), rel=RTOL)
        with pytest.raises(FMUError, match="finished"):
            st.step(3.0)  # superseded by the newer run


def test_states_are_not_accessible_in_co_simulation():
    with FMUModel(cs2_fmu()) as m:
        with pytest.raises(FMUError, match="co-simulation"):
            m.stepper().get_continuous_states()


# -- reuse, errors, cleanup ---------------------------------------------------------

def test_fifty_runs_reuse_one_extraction_and_instance(monkeypatch, fmu_path):
    calls = {"extract": 0, "instantiate": 0}
    import trackingbox.fmu as fmu_module

    real_extract, real_instantiate = fmu_module.isolation.extract, fmpy.simulation.instantiate_fmu

    def counting_extract(*a, **kw):
        calls["extract"] += 1
        return real_extract(*a, **kw)

    def counting_instantiate(*a, **kw):
        calls["instantiate"] += 1
        return real_instantiate(*a, **kw)

    monkeypatch.setattr(fmu_module.isolation, "extract", counting_extract)
    monkeypatch.setattr(fmpy.simulation, "instantiate_fmu", counting_instantiate)
    with FMUModel(fmu_path) as m:
        assert calls == {"extract": 1, "instantiate": 1}
        ks = 0.5 + 0.1 * np.arange(50)
        finals = [m.simulate(stop_time=1.0, output_interval=0.5, parameters={"k": k})["y"].iloc[-1] for k in ks]
        default = m.simulate(stop_time=1.0, output_interval=0.5)["y"].iloc[-1]
    assert calls == {"extract": 1, "instantiate": 1}
    assert np.allclose(finals, lag(1.0, 0.5, 1.0, ks), rtol=RTOL)
    # a run without parameters is back at the FMU's start values (k = 2)
    assert default == pytest.approx(lag(1.0, 0.5, 1.0, 2.0), rel=RTOL)


def test_unknown_names_in_simulate(model):
    with pytest.raises(FMUError, match=r"'yy'.*did you mean 'y'"):
        model.simulate(stop_time=1.0, output_interval=0.5, outputs=["yy"])
    with pytest.raises(FMUError, match=r"unknown variable 'kk'.*did you mean 'k'"):
        model.simulate(stop_time=1.0, output_interval=0.5, parameters={"kk": 1.0})
    with pytest.raises(FMUError, match=r"unknown input 'uu'.*did you mean 'u'"):
        model.simulate(stop_time=1.0, output_interval=0.5, inputs=pd.DataFrame({"time": [0.0], "uu": [1.0]}))


def test_bad_inputs_table(model):
    with pytest.raises(DataError, match="no 'time' column"):
        model.stepper(inputs=pd.DataFrame({"t": [0.0], "u": [1.0]}))
    with pytest.raises(DataError, match="strictly increasing"):
        model.stepper(inputs=pd.DataFrame({"time": [0.0, 2.0, 1.0], "u": [1.0, 1.0, 1.0]}))
    with pytest.raises(DataError, match=r"input 'u'.*1 NaN.*t = 1 s"):
        model.stepper(inputs=pd.DataFrame({"time": [0.0, 1.0], "u": [1.0, np.nan]}))


def test_solver_failure_names_the_time():
    # k = 0, p = 1: dx/dt = x^2, x(0) = 0.5 => x = 1 / (2 - t), infinite at t = 2
    # (errors grow like x^2 on the way: a tighter solver tolerance keeps the check at RTOL)
    with FMUModel(me2_fmu(), tolerance=1e-8) as m:
        st = m.stepper(parameters={"k": 0.0, "p": 1.0})
        st.step(1.5)
        assert st.get(["y"])[0] == pytest.approx(1 / (2 - 1.5), rel=RTOL)
        with pytest.raises(SimulationError, match=r"t = 1\.5 s and t = 3 s"):
            st.step(3.0)


def test_non_finite_output_names_variable_and_time():
    # u = -1: y = -1 + 1.5 exp(-2 t) < 0 from t = ln(1.5)/2 = 0.203 s, so z = sqrt(y) is NaN from t = 0.25
    with FMUModel(cs2_fmu()) as m:
        with pytest.raises(SimulationError, match=r"non-finite value of 'z' at t = 0\.25 s"):
            m.simulate(stop_time=1.0, output_interval=0.25, parameters={"u": -1.0})


def test_extraction_is_removed_on_close_and_on_gc():
    m = FMUModel(me3_fmu())
    tempdir = Path(m._tempdir)
    assert (tempdir / "modelDescription.xml").is_file()
    m.close()
    assert not tempdir.exists()
    with pytest.raises(FMUError, match="closed"):
        m.stepper()
    m2 = FMUModel(me3_fmu())
    tempdir2 = Path(m2._tempdir)
    del m2
    gc.collect()
    assert not tempdir2.exists()


def test_interface_not_offered():
    with pytest.raises(FMUError, match="does not provide the CoSimulation interface"):
        FMUModel(me3_fmu(), interface="CoSimulation")


def test_forked_child_dropping_a_model_keeps_the_parents_files():
    import os

    m = FMUModel(me3_fmu())
    tempdir = Path(m._tempdir)
    pid = os.fork()
    if pid == 0:  # child: drop the inherited model, as a pool initializer does
        try:
            del m
            gc.collect()
        finally:
            os._exit(0)
    os.waitpid(pid, 0)
    assert (tempdir / "modelDescription.xml").is_file()
    assert m.simulate(stop_time=1.0, output_interval=1.0)["y"].iloc[-1] == pytest.approx(
        lag(1.0, 0.5, 1.0, 2.0), rel=RTOL)
    m.close()
    assert not tempdir.exists()


# -- layout: one driver per interface, public methods only --------------------------

@pytest.mark.parametrize("name, driver", [("fmi3-me", "ModelExchangeStepper"), ("fmi2-me", "ModelExchangeStepper"),
                                          ("fmi2-cs", "CoSimulationStepper"), ("fmi3-cs", "CoSimulationStepper")])
def test_stepper_is_the_driver_of_the_interface_the_fmu_declares(name, driver):
    import trackingbox.fmu as fmu_module

    with FMUModel(FMUS[name]()) as m:
        st = m.stepper()
        # an event-free FMI 3 model-exchange FMU gets the native stepper, a ModelExchangeStepper too
        assert isinstance(st, getattr(fmu_module, driver))
        assert isinstance(st, fmu_module.Stepper)
        # the interface is the one in the model description
        declared = zipfile.ZipFile(FMUS[name]()).read("modelDescription.xml").decode()
        assert ("<ModelExchange" in declared) == (driver == "ModelExchangeStepper")
        m.stepper()  # a newer run finishes the old stepper
        with pytest.raises(FMUError, match="finished"):
            st.step(0.1)


def test_fmu_classes_use_no_private_attribute_of_another_object():
    """FMUModel and the steppers reach other objects through public names only (``self._x`` is fine)."""
    import ast

    import trackingbox.fmu as fmu_module

    # the classes live in the modules of the fmu package (model, steppers)
    trees = [ast.parse(path.read_text()) for path in sorted(Path(fmu_module.__file__).parent.glob("*.py"))]
    offending = []
    classes = [n for tree in trees for n in tree.body if isinstance(n, ast.ClassDef)
               and n.name in ("FMUModel", "Stepper", "ModelExchangeStepper", "CoSimulationStepper")]
    assert len(classes) == 4
    for cls in classes:
        for node in ast.walk(cls):
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                    and not (isinstance(node.value, ast.Name) and node.value.id == "self")):
                offending.append(f"{cls.name} line {node.lineno}: {ast.unparse(node)}")
    assert offending == []
