"""Algorithm sections in models and initial algorithm sections (issue 35, item 2): executed as
equations whose unknowns are the variables they assign, checked against closed-form solutions."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model
from trackingbox.errors import UnsupportedConstructError

pytestmark = pytest.mark.compile

MODELS = """
package Alg
  model Friction "an initial algorithm computes a fixed = false parameter (the MSL's SimpleFriction pattern)"
    parameter Real dpNominal = 5;
    parameter Real dpLaminar = 1;
    parameter Real V_flowNominal = 2;
    parameter Real V_flowLaminar = 1;
    parameter Real k(fixed = false, start = 0);
    Real x(start = 0, fixed = true);
  initial algorithm
    assert(V_flowNominal > V_flowLaminar, "V_flowNominal has to be > V_flowLaminar");
    k := (dpNominal - dpLaminar)/(V_flowNominal - V_flowLaminar)^2;
  equation
    der(x) = k;
  end Friction;
  model Sequence "an algorithm: assignments in order, reading what it assigned before"
    Real x(start = 1, fixed = true);
    Real y(start = 10);
  algorithm
    y := 2*x;
    if x > 1.6 then
      y := y + 1;
    end if;
    y := y + 6;
  equation
    der(x) = 1;
  end Sequence;
  model TwoOutputs "an algorithm assigning two variables: the rumoca front end refuses it"
    Real x(start = 1, fixed = true);
    Real y;
    Real z;
  algorithm
    y := 2*x;
    z := y + 1;
  equation
    der(x) = 1;
  end TwoOutputs;
  model Bad "the initial algorithm's assert fails: the FMU refuses to initialise"
    extends Friction(V_flowNominal = 0.5);
  end Bad;
  model Grows "an assert that fails between events, at t = 0.3 s"
    Real x(start = 0, fixed = true);
  equation
    der(x) = 1;
    assert(x < 0.3, "x has grown past 0.3");
  end Grows;
end Alg;
"""


@pytest.fixture(scope="module")
def pkg(tmp_path_factory):
    src = tmp_path_factory.mktemp("alg") / "Alg.mo"
    src.write_text(MODELS)
    return src


def test_an_initial_algorithm_computes_a_fixed_false_parameter(pkg, tmp_path):
    res = compile_model(pkg, "Alg.Friction", backend="embedded", output=tmp_path / "f.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=2.0, output_interval=0.5, output=["x", "k"])
    assert np.allclose(out["k"], 4.0)  # (5 - 1)/(2 - 1)^2
    assert np.allclose(out["x"], 4.0 * out["time"])
    # a changed parameter changes k: it follows the parameters as the user sets them
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, output=["k"],
                            start_values={"dpNominal": 9.0})
    assert np.allclose(out["k"], 8.0)


def test_an_algorithm_runs_its_statements_in_order(pkg, tmp_path):
    res = compile_model(pkg, "Alg.Sequence", backend="embedded", output=tmp_path / "s.fmu")
    # x > 1.6 is an event at t = 0.6: the output grid only (record_events=False) avoids the two rows there
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.25, output=["x", "y"],
                            relative_tolerance=1e-9, record_events=False)
    x = 1 + out["time"]
    assert np.allclose(out["x"], x)
    assert np.allclose(out["y"], 2 * x + (x > 1.6) + 6)


def test_an_algorithm_with_two_outputs_is_refused_naming_the_front_end(pkg, tmp_path):
    with pytest.raises(UnsupportedConstructError, match=r"multi-output algorithm .*not supported by the rumoca "
                       r"front end.* at .*Alg.mo:\d+"):
        compile_model(pkg, "Alg.TwoOutputs", backend="embedded", output=tmp_path / "t.fmu")


def test_a_failing_assert_of_an_initial_algorithm_stops_the_run(pkg, tmp_path):
    res = compile_model(pkg, "Alg.Bad", backend="embedded", output=tmp_path / "b.fmu")
    logged: list[str] = []

    def logger(*args):
        logged.append(" ".join(a.decode() if isinstance(a, bytes) else str(a) for a in args))

    with pytest.raises(Exception, match="fmi3ExitInitializationMode failed"):
        fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.5, logger=logger)
    assert any("assert failed at t = 0 s: V_flowNominal has to be > V_flowLaminar" in m for m in logged)


def test_an_assert_failing_between_events_stops_an_importer_that_follows_the_model_description(pkg, tmp_path):
    """fmpy calls fmi3CompletedIntegratorStep only where the model description asks for it
    (needsCompletedIntegratorStep); the asserts are checked there, so the FMU must ask, or an
    importer like fmpy runs on past a failed assert (x = 0.3 at t = 0.3 s, by hand)."""
    res = compile_model(pkg, "Alg.Grows", backend="embedded", output=tmp_path / "g.fmu")
    md = fmpy.read_model_description(str(res.fmu))
    assert md.modelExchange.needsCompletedIntegratorStep
    logged: list[str] = []

    def logger(*args):
        logged.append(" ".join(a.decode() if isinstance(a, bytes) else str(a) for a in args))

    with pytest.raises(Exception, match="fmi3CompletedIntegratorStep failed"):
        fmpy.simulate_fmu(str(res.fmu), stop_time=1.0, output_interval=0.05, logger=logger,
                          fmi_type="ModelExchange")
    failed = [m for m in logged if "assert failed at t = " in m and "x has grown past 0.3" in m]
    assert failed, logged
    t = float(failed[0].split("assert failed at t = ")[1].split(" s")[0])
    assert 0.3 <= t <= 0.35 + 1e-9, failed[0]
