"""MSL 4.0.0 examples through the embedded compiler, against the Modelica Association's reference
results in ../shared/msl-reference (issue 35): what the harness (scripts/msl) does, on a few examples."""
from __future__ import annotations

from pathlib import Path

import pytest

from trackingbox.compiler.msl_harness import default_msl, default_reference, run_example

pytestmark = pytest.mark.compile

MSL = default_msl()
REFERENCE = default_reference()


def _need_msl() -> None:
    if not (MSL / "package.mo").is_file():
        pytest.skip(f"the Modelica Standard Library is not at {MSL} (set TRACKINGBOX_MSL)")
    if not REFERENCE.is_dir():
        pytest.skip(f"the MSL reference results are not at {REFERENCE} (set TRACKINGBOX_MSL_REFERENCE)")


def run(model: str, tmp_path: Path) -> dict:
    _need_msl()
    # as a user compiles it: the library's directory only (ModelicaServices is found beside it)
    return run_example({"model": model, "source": str(MSL), "libraries": [], "reference": str(REFERENCE)})


def test_two_masses_matches_its_reference(tmp_path):
    res = run("Modelica.Thermal.HeatTransfer.Examples.TwoMasses", tmp_path)
    assert res["outcome"] == "match", res["message"]
    assert res["deviation"] <= 1e-3


def test_a_model_on_the_msl_finds_modelica_services_beside_it(tmp_path):
    """Compiled as a user does (the MSL's package directory only): ModelicaServices, which
    Modelica.Constants uses, is found beside it."""
    _need_msl()
    from trackingbox.compiler import compile_model

    model = tmp_path / "OneState.mo"
    model.write_text(
        "model OneState\n  Modelica.Thermal.HeatTransfer.Components.HeatCapacitor c(C = 1000, T(start = 350, "
        "fixed = true));\n  Modelica.Thermal.HeatTransfer.Components.ThermalConductor g(G = 10);\n"
        "  Modelica.Thermal.HeatTransfer.Sources.FixedTemperature amb(T = 290);\nequation\n"
        "  connect(c.port, g.port_a);\n  connect(g.port_b, amb.port);\nend OneState;\n")
    import fmpy
    import numpy as np

    res = compile_model(model, "OneState", backend="embedded", output=tmp_path / "o.fmu", libraries=[MSL])
    assert res.states == 1
    out = fmpy.simulate_fmu(str(res.fmu), stop_time=200.0, output_interval=50.0, output=["c.T"],
                            relative_tolerance=1e-9)
    # C dT/dt = -G (T - 290): T = 290 + 60 exp(-t G / C)
    assert np.allclose(out["c.T"], 290 + 60 * np.exp(-out["time"] * 10 / 1000), rtol=1e-7)
