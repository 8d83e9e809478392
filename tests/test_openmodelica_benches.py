"""The OpenModelica backend on the real benches, where ``omc`` is installed.

Every test here is marked ``openmodelica``: ``conftest.py`` skips them, with the
reason printed, only when ``omc`` is not on PATH (it cannot be installed on the
machines this project is developed on, so none of these has run here; see
docs/openmodelica.md). Where omc exists they check:

* the bench models (plant and twin of each bench) build and expose every Real
  parameter, input and output of the embedded path's FMU under the same name
  and causality (the twins' parameters also as ``tunable``, which ``pair`` and
  ``track`` need);
* the benches' validation wrappers (inputs bound to functions of time) simulate
  and agree with the embedded path's FMU within 0.1 % of each variable's range;
* a generated tracked model agrees with its embedded build within 0.1 % of range;
* a model using ``Modelica.Blocks.Continuous.PI`` (loaded through its ``uses``
  annotation) follows the PI's closed-form step response.
"""
from __future__ import annotations

from pathlib import Path

import fmpy
import numpy as np
import pytest

from trackingbox.compiler import compile_model, library_path
from trackingbox.compiler.omc_interface import ExpectedInterface, compare_interface

from _fixtures_generate import write_case
from _fixtures_benches import bench_models, validation_models

pytestmark = [pytest.mark.openmodelica, pytest.mark.compile, pytest.mark.slow]


@pytest.fixture(scope="module")
def om_cache(tmp_path_factory):
    root = tmp_path_factory.mktemp("om-fmus")
    done: dict[str, Path] = {}

    def get(model: str) -> Path:
        if model not in done:
            done[model] = compile_model(library_path(), model, backend="openmodelica",
                                        output=root / f"{model}.fmu").fmu
        return done[model]

    return get


def _agreement(a: Path, b: Path, stop: float, names: list[str], inputs=None) -> list[tuple[str, float, float]]:
    """Variables whose two simulations differ by more than 0.1 % of their range: (name, error, range)."""
    kw = dict(stop_time=stop, output_interval=stop / 400, output=names, relative_tolerance=1e-8)
    if inputs is not None:
        kw["input"] = inputs
    ra, rb = fmpy.simulate_fmu(str(a), **kw), fmpy.simulate_fmu(str(b), **kw)
    worst = []
    for name in names:
        x, y = np.asarray(ra[name], float), np.asarray(rb[name], float)
        span = max(np.ptp(x), 1e-6 * max(1.0, float(np.max(np.abs(x)))))
        err = float(np.max(np.abs(x - y)))
        if err > 1e-3 * span:
            worst.append((name, err, span))
    return worst


@pytest.mark.parametrize("model", bench_models())
def test_bench_model_exposes_the_embedded_names(fmu_cache, om_cache, model):
    om = om_cache(model)
    md = fmpy.read_model_description(str(om))
    assert md.fmiVersion == "2.0" and md.modelExchange is not None and md.coSimulation is not None
    report = compare_interface(om, ExpectedInterface.from_fmu(fmu_cache(model)), require_tunable=False)
    assert report.ok, "\n".join(str(p) for p in report.problems)


@pytest.mark.parametrize("model", [m for m in bench_models() if m.endswith(".Twin")])
def test_bench_twin_parameters_are_tunable(fmu_cache, om_cache, model):
    """pair and track change the twin's parameters between steps: they must be ``tunable``."""
    expected = ExpectedInterface(parameters=ExpectedInterface.from_fmu(fmu_cache(model)).parameters)
    report = compare_interface(om_cache(model), expected)
    assert report.ok, "\n".join(str(p) for p in report.problems)


@pytest.mark.parametrize("model", validation_models())
def test_validation_wrapper_agrees_with_the_embedded_path(fmu_cache, om_cache, model):
    emb, om = fmu_cache(model), om_cache(model)
    md_e, md_o = fmpy.read_model_description(str(emb)), fmpy.read_model_description(str(om))
    stop = float(md_e.defaultExperiment.stopTime)
    om_names = {v.name for v in md_o.modelVariables}
    names = sorted(v.name for v in md_e.modelVariables
                   if v.name in om_names and v.causality != "parameter" and v.variability == "continuous")
    assert names, "no common variables to compare"
    worst = _agreement(emb, om, stop, names)
    assert not worst, f"{len(worst)} of {len(names)} variables differ by more than 0.1 % of their range: {worst[:5]}"


def test_generated_tracked_model_agrees_with_the_embedded_path(tmp_path):
    from trackingbox.generate.generator import compile_generated, generate
    from trackingbox.spec import load_spec

    result = generate(load_spec(write_case(tmp_path / "case"), check_files=False), tmp_path / "out")
    emb = compile_generated(result, backend="embedded", output=tmp_path / "emb.fmu").fmu
    om = compile_generated(result, backend="openmodelica", output=tmp_path / "om.fmu")
    assert om.fmi_version == "2.0"
    inputs = np.array([(0.0, 50000.0, 305.5, 0.0), (4000.0, 50000.0, 305.5, 0.0)],
                      dtype=[("time", float), ("Qin", float), ("TI_102_meas", float), ("hold", float)])
    worst = _agreement(emb, om.fmu, 4000.0, ["hx_kht", "ThOut"], inputs)
    assert not worst, worst


PI_MODEL = '''within;
model PIStep "A PI controller from the Modelica Standard Library on a unit step"
  Modelica.Blocks.Continuous.PI pi(k = 2, T = 10, initType = Modelica.Blocks.Types.Init.InitialState,
    x_start = 0) "y = k (x + u), der(x) = u/T";
  Modelica.Blocks.Sources.Constant one(k = 1) "Unit input";
  output Real y "Controller output";
equation
  connect(one.y, pi.u);
  y = pi.y;
  annotation(uses(Modelica(version = "4.0.0")), experiment(StopTime = 20));
end PIStep;
'''


def test_msl_pi_model_follows_the_closed_form(tmp_path):
    (tmp_path / "PIStep.mo").write_text(PI_MODEL)
    res = compile_model(tmp_path / "PIStep.mo", "PIStep", backend="openmodelica", output=tmp_path / "pi.fmu")
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=20.0, output_interval=0.5, output=["y"],
                            relative_tolerance=1e-8)
    expected = 2.0 * (1.0 + out["time"] / 10.0)  # k (u + u t / T) with x(0) = 0
    assert np.allclose(out["y"], expected, rtol=1e-6, atol=1e-8)
