"""The issue's case on a model built from the Modelica Standard Library: a wall of two thermal resistors
and a heat capacitor (``Modelica.Thermal.HeatTransfer``), seen through its temperature.

Independent expectation: the physics. ``C dT/dt = (T_in - T)/R1 - (T - T_out)/R2`` depends on the
parameters only through ``R1·C`` and ``R2·C``, so ``identify`` must name exactly that, the estimate's
individual values are arbitrary along the valley, and the combinations' intervals must cover the
plant's ``R1·C = 4000 s`` and ``R2·C = 10000 s``. The unmeasured heat flow ``Q_inside = (T_in - T)/R1``
does depend on R1 alone, so it is the output that would tell them apart.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from trackingbox.identify.thermal import TRUTH, compile_wall, wall_case

pytestmark = pytest.mark.compile

MSL = Path(__file__).resolve().parents[1].parent / "shared" / "msl"
needs_msl = pytest.mark.skipif(not (MSL / "Modelica" / "package.mo").is_file(),
                               reason=f"the Modelica Standard Library is not at {MSL} (../shared/msl)")


@pytest.fixture(scope="module")
def wall(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The spec of a 24 h wall case (seed 2), the twin compiled from the MSL once."""
    root = tmp_path_factory.mktemp("wall")
    fmu = compile_wall(root / "wall.fmu", MSL)
    return wall_case(root / "case", fmu, seed=2, hours=24.0)


@needs_msl
def test_identify_names_the_products_and_the_sensor_that_would_separate_them(wall: Path) -> None:
    from trackingbox.identify.analysis import identify
    from trackingbox.spec import load_spec

    found = identify(load_spec(wall), points=2)
    assert found.rank == 2 and not any(found.determined.values())
    (f,) = found.findings
    assert f.kind == "product" and set(f.parameters) == {"R1", "R2", "C"}
    assert sorted(c.text for c in f.determined) == ["R1·C", "R2·C"]
    assert f.structural and f.consistent
    assert f.candidates and f.candidates[0][0] == "Q_inside"
    assert "only R1·C and R2·C are determined" in f.message


@needs_msl
def test_estimate_reports_the_determined_combinations_with_intervals_that_cover_the_truth(wall: Path) -> None:
    from trackingbox.spec import load_spec
    from trackingbox.stages import estimate

    result = estimate.run(load_spec(wall), estimate.EstimateSettings(maxiter=4))
    unc = result.uncertainty
    assert unc is not None
    for name in ("R1", "R2", "C"):
        iv = unc.interval(name)
        assert not iv.determined and iv.lower is None
        assert iv.text().startswith("not determined (with ") and "only R1·C and R2·C are" in iv.text()
    truth = {"R1·C": TRUTH["R1"] * TRUTH["C"], "R2·C": TRUTH["R2"] * TRUTH["C"]}
    assert sorted(iv.name for iv in unc.combinations) == sorted(truth)
    for iv in unc.combinations:
        assert iv.covers(truth[iv.name]), iv.text()
        assert (iv.upper - iv.lower) < 0.05 * truth[iv.name]  # and they are informative: within +-2.5 %
    doc = result.to_json()["uncertainty"]
    assert doc["parameters"]["C"]["lower"] is None and doc["combinations"][0]["combination"]["kind"] == "product"
