"""The embedded compile path: Modelica source → FMI 3.0 model-exchange FMU.

Expectations are independent of the code under test: closed-form solutions,
hand-solved steady states, rumoca's own integrator, and fmpy's validator.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import fmpy
import numpy as np
import pytest
import rumoca
from fmpy.validation import validate_fmu

from trackingbox.cli import main
from trackingbox.compiler import compile_model
from trackingbox.errors import CompileError, UnsupportedConstructError

pytestmark = pytest.mark.compile


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def simulate(fmu: Path, stop: float, interval: float, **kw) -> np.ndarray:
    return fmpy.simulate_fmu(str(fmu), stop_time=stop, output_interval=interval, **kw)


FIRST_ORDER = """
model FirstOrder "dx/dt = (k*u - x)/tau with y = x"
  parameter Real k(min = 0.1, max = 10, unit = "1") = 2 "Gain";
  parameter Real tau(unit = "s") = 5 "Time constant";
  parameter Real twoK = 2*k "Calculated from k";
  input Real u(start = 1.5) "Input";
  Real x(start = 0.5, fixed = true) "State";
  output Real y "Output";
equation
  der(x) = (k*u - x)/tau;
  y = x;
  annotation(experiment(StopTime = 20, Tolerance = 1e-8));
end FirstOrder;
"""


def test_first_order_matches_closed_form(tmp_path):
    src = write(tmp_path, "FirstOrder.mo", FIRST_ORDER)
    res = compile_model(src, "FirstOrder", backend="embedded", output=tmp_path / "fo.fmu")
    assert res.fmi_version == "3.0" and res.states == 1 and res.backend == "embedded"
    assert validate_fmu(str(res.fmu)) == []
    out = simulate(res.fmu, 20, 0.5, output=["y", "twoK"], relative_tolerance=1e-8)
    t = out["time"]
    expected = 3.0 + (0.5 - 3.0) * np.exp(-t / 5)  # x(∞) = k*u = 3
    assert np.allclose(out["y"], expected, atol=1e-5)
    assert np.allclose(out["twoK"], 4.0)


def test_exports_attributes_and_causality(tmp_path):
    src = write(tmp_path, "FirstOrder.mo", FIRST_ORDER)
    res = compile_model(src, "FirstOrder", backend="embedded", output=tmp_path / "fo.fmu")
    md = fmpy.read_model_description(str(res.fmu))
    by_name = {v.name: v for v in md.modelVariables}
    k = by_name["k"]
    assert (k.causality, k.variability) == ("parameter", "tunable")
    assert float(k.start) == 2.0 and float(k.min) == 0.1 and float(k.max) == 10.0
    assert k.description == "Gain"
    assert by_name["u"].causality == "input" and float(by_name["u"].start) == 1.5
    assert by_name["y"].causality == "output"
    assert by_name["x"].causality == "local" and float(by_name["x"].start) == 0.5
    assert by_name["twoK"].causality == "local"  # a calculated parameter, not settable
    assert md.defaultExperiment is not None and float(md.defaultExperiment.stopTime) == 20


def test_tunable_parameter_changes_calculated_values(tmp_path):
    src = write(tmp_path, "FirstOrder.mo", FIRST_ORDER)
    res = compile_model(src, "FirstOrder", backend="embedded", output=tmp_path / "fo.fmu")
    out = simulate(res.fmu, 60, 1.0, start_values={"k": 4.0, "u": 1.0}, output=["y", "twoK"])
    assert math.isclose(out["twoK"][-1], 8.0)
    assert math.isclose(out["y"][-1], 4.0, rel_tol=1e-4)  # steady state k*u


LOOP = """
model Loop "nonlinear algebraic loop: z + exp(z)/10 = x, and a linear 2x2 loop"
  Real x(start = 1, fixed = true);
  Real z(start = 0);
  Real a;
  Real b;
equation
  der(x) = -0.1*x;
  z + exp(z)/10 = x;
  a + 2*b = x;
  3*a - b = 1;
end Loop;
"""


def test_algebraic_loops_are_solved(tmp_path):
    src = write(tmp_path, "Loop.mo", LOOP)
    res = compile_model(src, "Loop", backend="embedded", output=tmp_path / "loop.fmu")
    out = simulate(res.fmu, 10, 1.0, output=["x", "z", "a", "b"])
    x = out["x"]
    assert np.allclose(x, np.exp(-0.1 * out["time"]), atol=1e-5)
    assert np.allclose(out["z"] + np.exp(out["z"]) / 10, x, atol=1e-8)
    # hand-solved: a = (x + 2)/7, b = (3x - 1)/7
    assert np.allclose(out["a"], (x + 2) / 7, atol=1e-9)
    assert np.allclose(out["b"], (3 * x - 1) / 7, atol=1e-9)


LIBRARY = """
package Lib
  connector RealInput = input Real;
  connector RealOutput = output Real;
  connector Port
    Real T "temperature";
    flow Real Q "heat flow";
  end Port;
  function clampedGain "if-statement, for-loop and protected local"
    input Real u;
    input Integer n;
    output Real y;
  protected
    Real acc;
  algorithm
    acc := 0;
    for i in 1:n loop
      acc := acc + u;
    end for;
    if acc > 10 then
      y := 10;
    else
      y := acc;
    end if;
  end clampedGain;
  model Capacity
    parameter Real C = 10 "Heat capacity";
    Port port;
    Real T(start = 300, fixed = true);
  equation
    C*der(T) = port.Q;
    port.T = T;
  end Capacity;
  model Conductor
    parameter Boolean use_G_in = false;
    parameter Real G = 1 "Conductance";
    RealInput G_in if use_G_in;
    Port a;
    Port b;
  protected
    RealInput G_int;
  equation
    connect(G_in, G_int);
    if not use_G_in then
      G_int = G;
    end if;
    a.Q = G_int*(a.T - b.T);
    a.Q + b.Q = 0;
  end Conductor;
  model Chain
    parameter Integer n = 3;
    Capacity cap[n](each C = 10, T(start = {400, 300, 200}));
    Conductor cond[n - 1](each G = 2);
    RealOutput Tmean;
    RealOutput g = clampedGain(noEvent(abs(cap[1].T - 300))/100, 4);
  equation
    for i in 1:n - 1 loop
      connect(cap[i].port, cond[i].a);
      connect(cond[i].b, cap[i + 1].port);
    end for;
    Tmean = sum(cap.T)/n;
  end Chain;
end Lib;
"""


def test_library_constructs_match_rumoca(tmp_path):
    """Packages, arrays of components, for-connect, flow, functions, conditional inputs."""
    src = write(tmp_path, "Lib.mo", LIBRARY)
    res = compile_model(src, "Lib.Chain", backend="embedded", output=tmp_path / "chain.fmu")
    assert res.states == 3
    out = simulate(res.fmu, 20, 0.5, output=["Tmean", "cap[1].T", "cap[3].T", "g"], relative_tolerance=1e-8)
    # energy is conserved: the mean temperature of equal capacities stays 300 K
    assert np.allclose(out["Tmean"], 300.0, atol=1e-6)
    ref = rumoca.Session().load(str(src), model="Lib.Chain").simulate((0, 20), dt=0.05)
    for name in ("cap[1].T", "cap[3].T", "g"):
        r = np.interp(out["time"], np.asarray(ref.time), np.asarray(ref[name]))
        span = max(np.ptp(r), 1e-9)
        assert np.max(np.abs(out[name] - r)) <= 1e-3 * span, name
    # g = min(4*|T1-300|/100, 10): at t=0, |400-300|/100*4 = 4
    assert math.isclose(out["g"][0], 4.0, rel_tol=1e-9)


def test_package_directory_source(tmp_path, library):
    model = "TrackingBox.Blocks.Validation.PIHoldAndLimits"
    res = compile_model(library, model, backend="embedded", output=tmp_path / "pi.fmu")
    assert res.fmu.is_file() and validate_fmu(str(res.fmu)) == []
    # the class compiled from the package directory behaves as rumoca simulates it from the same
    # package: setpoint step at 200 s, hold from 600 s to 900 s
    out = simulate(res.fmu, 1500, 5.0, output=["x", "con.y"], relative_tolerance=1e-8)
    ref = rumoca.Session().load(str(library / "package.mo"), model=model).simulate((0, 1500), dt=1.0)
    for name in ("x", "con.y"):
        r = np.interp(out["time"], np.asarray(ref.time), np.asarray(ref[name]))
        assert np.max(np.abs(out[name] - r)) <= 1e-3 * max(np.ptp(r), 1e-9), name
    # integral action: no steady offset after the step (0.9), before the hold and after it
    assert np.interp([590.0, 1500.0], out["time"], out["x"]) == pytest.approx([0.9, 0.9], abs=1e-3)


# ------------------------------------------------------------------ bad input
def test_syntax_error_names_file_and_line(tmp_path):
    src = write(tmp_path, "Bad.mo", "model Bad\n  Real x;\nequation\n  x = ;\nend Bad;\n")
    with pytest.raises(CompileError) as exc:
        compile_model(src, "Bad", backend="embedded", output=tmp_path / "bad.fmu")
    assert "Bad.mo:4" in str(exc.value)
    assert not (tmp_path / "bad.fmu").exists()


def test_unknown_class(tmp_path):
    src = write(tmp_path, "FirstOrder.mo", FIRST_ORDER)
    with pytest.raises(CompileError) as exc:
        compile_model(src, "SecondOrder", backend="embedded", output=tmp_path / "x.fmu")
    assert "SecondOrder" in str(exc.value)
    assert not (tmp_path / "x.fmu").exists()


@pytest.mark.parametrize(
    "body, construct, line",
    [
        ("  Real x(start=0, fixed=true);\nequation\n  der(x) = 1;\n  when x > 1 then\n    terminate(\"done\");\n"
         "  end when;\n", "terminate() in a when-clause", 6),
        ("  Real x(start=0, fixed=true);\n  Real y;\nequation\n  der(x) = 1;\n  y = delay(x, 1.0);\n", "delay", 6),
    ],
)
def test_unsupported_construct_is_refused_with_location(tmp_path, body, construct, line):
    src = write(tmp_path, "U.mo", "model U\n" + body + "end U;\n")
    with pytest.raises(UnsupportedConstructError) as exc:
        compile_model(src, "U", backend="embedded", output=tmp_path / "u.fmu")
    msg = str(exc.value)
    assert construct in msg and f"U.mo:{line}" in msg
    assert not (tmp_path / "u.fmu").exists()


def test_reinit_of_a_variable_that_is_not_a_state_is_an_error_at_its_line(tmp_path):
    src = write(tmp_path, "R.mo", "model R\n  Real x(start=0, fixed=true);\n  Real y;\nequation\n  der(x) = 1;\n"
                "  y = x;\n  when x > 1 then\n    reinit(y, 0);\n  end when;\nend R;\n")
    with pytest.raises(CompileError, match=r"reinit\(\) can only be applied to state variables.*R\.mo:8"):
        compile_model(src, "R", backend="embedded", output=tmp_path / "r.fmu")
    assert not (tmp_path / "r.fmu").exists()


def test_structurally_singular_model(tmp_path):
    """Balanced in count, but y appears in no equation and x in two."""
    src = write(tmp_path, "S.mo", "model S\n  Real x;\n  Real y;\nequation\n  x = 1;\n  2*x = time;\nend S;\n")
    with pytest.raises(CompileError) as exc:
        compile_model(src, "S", backend="embedded", output=tmp_path / "s.fmu")
    msg = str(exc.value)
    assert "structurally singular" in msg and "y" in msg.split("not determined by any equation:")[1]
    assert not (tmp_path / "s.fmu").exists()


def test_unknown_class_in_package_suggests_names(tmp_path, library):
    with pytest.raises(CompileError) as exc:
        compile_model(library, "TrackingBox.Benches.HeatExchanger.Twinn", backend="embedded",
                      output=tmp_path / "x.fmu")
    assert "did you mean 'TrackingBox.Benches.HeatExchanger.Twin'" in str(exc.value)


def test_missing_source(tmp_path):
    with pytest.raises(CompileError, match="does not exist"):
        compile_model(tmp_path / "nope.mo", "Nope", backend="embedded")


# ------------------------------------------------------------------------ CLI
def test_cli_compile_json(tmp_path, capsys):
    src = write(tmp_path, "FirstOrder.mo", FIRST_ORDER)
    out = tmp_path / "cli.fmu"
    code = main(["compile", str(src), "--model", "FirstOrder", "--backend", "embedded", "-o", str(out), "--json"])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["fmu"] == str(out) and doc["fmi_version"] == "3.0" and doc["states"] == 1
    assert doc["parameters"] == 2 and doc["backend"] == "embedded" and doc["seconds"] > 0
    assert out.is_file()


def test_cli_compile_error_exit_code(tmp_path, capsys):
    src = write(tmp_path, "Bad.mo", "model Bad\n  Real x;\nequation\n  x = ;\nend Bad;\n")
    out = tmp_path / "bad.fmu"
    code = main(["compile", str(src), "--model", "Bad", "--backend", "embedded", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error:") and "Traceback" not in err
    assert not out.exists()


@pytest.mark.openmodelica
def test_openmodelica_backend_builds_fmi2(tmp_path):
    src = write(tmp_path, "FirstOrder.mo", FIRST_ORDER)
    res = compile_model(src, "FirstOrder", backend="openmodelica", output=tmp_path / "om.fmu")
    assert res.fmi_version == "2.0"
    out = simulate(res.fmu, 20, 0.5, output=["y"])
    assert np.allclose(out["y"], 3.0 + (0.5 - 3.0) * np.exp(-out["time"] / 5), atol=1e-4)


def test_parameter_only_in_start_values_is_not_offered(tmp_path):
    """A tunable parameter that cannot change anything must not be offered as one."""
    src = write(tmp_path, "S0.mo", """
model S0
  parameter Real x_start = 2 "Only sets a start value";
  parameter Real a = 0.5 "Decay rate";
  Real x(start = x_start, fixed = true);
equation
  der(x) = -a*x;
end S0;
""")
    res = compile_model(src, "S0", backend="embedded", output=tmp_path / "s0.fmu")
    names = {v.name for v in fmpy.read_model_description(str(res.fmu)).modelVariables}
    assert "a" in names and "x_start" not in names and "x_start" in res.log
    out = simulate(res.fmu, 2, 1.0, output=["x"], start_values={"x": 4.0}, relative_tolerance=1e-9)
    assert np.allclose(out["x"], 4.0 * np.exp(-0.5 * out["time"]), rtol=1e-5)


CHAIN = """
model Chain "a pump curve against n linear resistances in series: one flow, n+1 pressures"
  parameter Integer n = 8;
  parameter Real R = 2 "resistance per pipe";
  parameter Real dp0 = 100 "shut-off head";
  parameter Real c = 1 "pump curve coefficient";
  Real p[n + 1];
  Real m(start = 1);
  Real x(start = 0, fixed = true);
equation
  p[1] = dp0 - c*m*abs(m);
  for i in 1:n loop
    p[i] - p[i + 1] = R*m;
  end for;
  p[n + 1] = 0;
  der(x) = m;
end Chain;
"""


def test_algebraic_loop_is_torn_to_its_flow(tmp_path):
    """p[n+1] = 0 stands alone; the other n+1 equations form one loop, torn at one variable."""
    src = write(tmp_path, "Chain.mo", CHAIN)
    res = compile_model(src, "Chain", backend="embedded", output=tmp_path / "chain.fmu")
    assert "9->1" in res.log  # p[1..8] and m: one loop, a single tearing variable
    out = simulate(res.fmu, 1, 0.5, output=["m", "p[1]", "p[5]", "x"])
    n, R, dp0 = 8, 2.0, 100.0
    m = (-n * R + math.sqrt((n * R) ** 2 + 4 * dp0)) / 2  # positive root of m^2 + nR m - dp0 = 0
    assert np.allclose(out["m"], m, rtol=1e-9)
    assert np.allclose(out["p[5]"], (n - 4) * R * m, rtol=1e-9)
    assert np.allclose(out["x"], m * out["time"], rtol=1e-6)


def test_model_without_states_follows_time(tmp_path):
    """No state, so no state update between steps: the outputs must still follow time
    (CasADi's generated fmi3SetTime kept its cached evaluation; the export patches it)."""
    src = write(tmp_path, "Clock.mo", """
model Clock
  parameter Real a = 2;
  output Real y;
  output Real z;
equation
  y = a*time;
  z = sin(time) + y;
end Clock;
""")
    res = compile_model(src, "Clock", backend="embedded", output=tmp_path / "clock.fmu")
    out = simulate(res.fmu, 2, 0.25, output=["y", "z"])
    assert len(out) == 9
    assert np.allclose(out["y"], 2 * out["time"], rtol=1e-12)
    assert np.allclose(out["z"], np.sin(out["time"]) + 2 * out["time"], rtol=1e-12)


def _misplaced_package(tmp_path: Path) -> Path:
    root = tmp_path / "P"
    root.mkdir()
    (root / "package.mo").write_text("package P\n  package Base\n    model M\n      Real x(start=1, fixed=true);\n"
                                     "    equation\n      der(x) = -x;\n    end M;\n  end Base;\n"
                                     "  package Derived\n    extends Base;\n  end Derived;\n"
                                     "  package Sub\n  end Sub;\nend P;\n")
    return root


def test_misplaced_class_is_refused_from_the_index_before_the_front_end(tmp_path, monkeypatch):
    """`P.Sub.M` does not exist (M is in P.Base): the index says so, naming the package that lacks
    it and where M is, without the front end parsing the library (which took about a minute on
    the MSL for a misspelt example name)."""
    import trackingbox.compiler.embedded as embedded

    def never(*a, **k):
        raise AssertionError("the front end ran for a class the index shows is absent")

    monkeypatch.setattr(embedded, "run_frontend", never)
    with pytest.raises(CompileError) as exc:
        compile_model(_misplaced_package(tmp_path), "P.Sub.M", backend="embedded", output=tmp_path / "x.fmu")
    msg = str(exc.value)
    assert "P.Sub has no class 'M'" in msg and "did you mean 'P.Base.M'" in msg
    assert not (tmp_path / "x.fmu").exists()


def test_class_inherited_into_a_package_is_left_to_the_front_end(tmp_path, monkeypatch):
    """`P.Derived.M` is M reached through `extends Base` (MLS 5.6): it exists, so the index must not
    refuse it; the front end is asked (rumoca 0.10.2 itself does not take an inherited class as the
    model to compile, which is its answer to give, not the index's)."""
    import trackingbox.compiler.embedded as embedded

    asked = []
    real = embedded.run_frontend

    def spy(source, model, *a, **k):
        asked.append(model)
        return real(source, model, *a, **k)

    monkeypatch.setattr(embedded, "run_frontend", spy)
    try:
        compile_model(_misplaced_package(tmp_path), "P.Derived.M", backend="embedded", output=tmp_path / "m.fmu")
    except CompileError as exc:
        assert "P.Derived has no class" not in str(exc)
    assert asked and asked[0] == "P.Derived.M"
