"""Heat-production bench end to end: bench -> ``trackingbox pair`` (defaults) -> ``track``.

Issue 15's Done criteria: ``pair`` finds at least four pairs, at least two of
them hydraulic (a pipe, valve or pump parameter), each physically sensible
(the parameter's component sits in the line whose tag it tracks); tracking on
the validation window, with the gains and time constants ``pair`` measured in
its step tests (none pasted), brings the NRMSE of *every* paired variable to
at most 30 % of the untracked twin's; no parameter leaves its bounds and no
twin tank empties or overflows.

A 12 h bench (6 h training, 6 h validation) keeps the run short; the step
tests do not depend on the length.
"""
from __future__ import annotations

import json

import pytest

#: Which tags each candidate parameter can sensibly track: the temperatures of its own
#: exchanger, or the pressure, flow or pump speed of the line its component sits in.
#: PU100 line: T100 -> PU100 -> Pipe100 -> V100 -> T200 (PI-100 at the pump's discharge);
#: PU200 loop: T200 -> PU200 -> Pipe200 -> V200 -> HU300 -> HEX300 -> Pipe201 -> V300 -> T100
#: (PI-200 at the discharge, PI-300 in HU300 after V200); make-up: T400 -> Pipe101 -> V400 -> T100.
_LINE_100 = {"PI-100", "FI-100", "SI-100"}
_LINE_200 = {"PI-200", "FI-200", "SI-200"}
SENSIBLE = {
    "HEX300.kht": {"TI-301", "TI-302"},
    "HU300.kht": {"TI-300", "TI-310"},
    "Pipe100.k": _LINE_100, "V100.KvMax": _LINE_100, "PU100.uRise": _LINE_100, "PU100.VFlowDesign": _LINE_100,
    "Pipe200.k": _LINE_200, "V200.KvMax": _LINE_200, "PU200.uRise": _LINE_200, "PU200.VFlowDesign": _LINE_200,
    "Pipe201.k": _LINE_200 | {"PI-300"}, "V300.KvMax": _LINE_200 | {"PI-300"},
    "Pipe101.k": {"FI-101", "ZI-400"}, "V400.KvMax": {"FI-101", "ZI-400"},
}


def _hydraulic(parameter: str) -> bool:
    """A pipe, valve or pump parameter (not a heat-transfer coefficient)."""
    return parameter.split(".")[0].startswith(("Pipe", "PU", "V"))


def test_sensible_table_by_hand() -> None:
    assert {p for p in SENSIBLE if _hydraulic(p)} == set(SENSIBLE) - {"HEX300.kht", "HU300.kht"}


@pytest.mark.slow
@pytest.mark.compile
def test_pair_then_track_heat_production(fmu_cache, tmp_path, capsys):
    from trackingbox.benches import make_bench
    from trackingbox.cli import main
    from trackingbox.spec import load_spec
    from trackingbox.tracking.runtime import track

    hp = "TrackingBox.Benches.HeatProduction"
    make_bench("heat-production", tmp_path / "case", seed=1, hours=12.0,
               plant_fmu=fmu_cache(f"{hp}.Plant"), twin_fmu=fmu_cache(f"{hp}.Twin"))
    spec_path = tmp_path / "case" / "spec.toml"
    assert main(["pair", str(spec_path), "--json", "--workers", "2"]) == 0
    doc = json.loads(capsys.readouterr().out)
    pairs = {p["variable"]: p["parameter"] for p in doc["pairs"]}
    assert len(pairs) >= 4, doc["left_out"]
    assert sum(_hydraulic(p) for p in pairs.values()) >= 2, pairs
    assert all(tag in SENSIBLE[par] for tag, par in pairs.items()), pairs
    by_param = {p: v for v, p in pairs.items()}
    assert by_param.get("HEX300.kht") in SENSIBLE["HEX300.kht"], pairs
    assert by_param.get("HU300.kht") in SENSIBLE["HU300.kht"], pairs
    # no parameter range closes the make-up flow offset (the valve coefficient's whole range moves
    # the flow by a few percent of it): it must not be paired, and the reason says so
    reasons = {d["name"]: d["reason"] for d in doc["left_out"]}
    assert "FI-400" not in pairs and "close its offset" in reasons["FI-400"], reasons.get("FI-400")
    # the second operating point is the high-load part of the training window
    assert doc["second_operating_point"]["inputs"]["mCold_flow"] > 1.3 * doc["operating_point"]["mCold_flow"]
    # every variable has data figures; the thresholds are reported
    assert {o["variable"] for o in doc["offsets"]} == set(doc["gain_matrix"]["variables"])
    assert doc["data_checks"] == {"noise_ratio": 5.0, "min_reach": 0.5, "max_ratio": 0.25}

    spec = load_spec(spec_path)
    assert {(p.variable, p.parameter) for p in spec.pairs} == set(pairs.items())
    result = track(spec, out_dir=tmp_path / "track", window="validation")
    for tag in pairs:
        v = result.variables[tag]
        assert v.nrmse_tracked <= 0.3 * v.nrmse_untracked, (tag, pairs[tag], v)
    for name, p in result.parameters.items():
        assert p.lower <= p.min <= p.max <= p.upper, (name, p)
    # no twin tank empties or overflows (inlets sit 1.2-1.5 m above the bottoms)
    for tag, level in result.states.items():
        assert 0.3 < level.min and level.max < 1.2, (tag, level)
