"""MSL 4.0.0 examples through the embedded compiler, against the Modelica Association's reference
results in ../shared/msl-reference (issue 35): what the harness (scripts/msl) does, on a few examples."""
from __future__ import annotations

from pathlib import Path

import pytest

from trackingbox.compiler.msl_harness import default_msl, default_reference, run_example, siblings

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
    return run_example({"model": model, "source": str(MSL), "libraries": [str(p) for p in siblings(MSL)],
                        "reference": str(REFERENCE)})


def test_two_masses_matches_its_reference(tmp_path):
    res = run("Modelica.Thermal.HeatTransfer.Examples.TwoMasses", tmp_path)
    assert res["outcome"] == "match", res["message"]
    assert res["deviation"] <= 1e-3
