"""Modelica.Fluid examples through the embedded compiler against the Modelica Association's reference
results in ../shared/msl-reference (issue 35), as the harness (scripts/msl) runs them.

``AST_BatchPlant.Test.TankWithEmptyingPipe2`` needs what the Fluid vessels are made of: the medium's
functions through its ``ThermodynamicState`` record (``density(setState_phX(...))``), a record
variable set whole from a function (the valve's ``state_a``), a wall-friction function called with a
pipe's vector of diameters for its scalar input (vectorised), and the ``inner`` system's
``energyDynamics = FixedInitial`` reaching the vessel's initial equations through ``outer``."""
from __future__ import annotations

import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler.msl_harness import default_reference, run_example

pytestmark = pytest.mark.compile

REFERENCE = default_reference()


def test_a_tank_emptying_through_a_pipe_matches_its_reference():
    need_msl("Fluid", "Examples", "AST_BatchPlant.mo")
    model = "Modelica.Fluid.Examples.AST_BatchPlant.Test.TankWithEmptyingPipe2"
    if not (REFERENCE / "Modelica" / "Fluid" / "Examples").is_dir():
        pytest.skip(f"the MSL reference results are not at {REFERENCE} (set TRACKINGBOX_MSL_REFERENCE)")
    res = run_example({"model": model, "source": str(MSL), "libraries": [], "reference": str(REFERENCE)})
    assert res["outcome"] == "match", res.get("message")
    assert res["deviation"] <= 1e-3
