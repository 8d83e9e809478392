"""The README's main job, ``scripts/demo``, run end to end on a short window.

``scripts/demo`` runs ``python -m trackingbox.demo``; this calls the same
``main`` with one hour of heat-exchanger data (``--hours 1``). The run takes
about 40 s of CPU (3 min wall on a loaded 2-core machine): every stage
(bench, untracked offset, estimate, pair, track, generate + compile, validate)
and the report. The figures are checked against the bench's truth
(``truth.json``, written by the bench, never read by the pipeline).
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from trackingbox.demo import STEPS, main


@pytest.mark.slow
@pytest.mark.compile
def test_demo_runs_every_stage_on_one_hour_of_the_heat_exchanger(tmp_path: Path, capsys) -> None:
    out = tmp_path / "demo"
    assert main(["--bench", "heat-exchanger", "--hours", "1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert str(out / "report.md") in printed and str(out / "report.html") in printed
    summary = json.loads((out / "summary.json").read_text())
    assert [s for s in ("estimate", "pair", "track", "generate", "validate") if s not in summary] == []
    assert len(STEPS) == 7
    kht = float(json.loads(Path(summary["bench_case"]["truth_file"]).read_text())["parameters"]["hx.kht"])
    assert summary["bench_case"]["hours"] == pytest.approx(1.0)
    # estimation on the half-hour training window finds the plant's fouled kht (noise: 0.1 K on
    # ~5 K of response, so a few W/(m2.K) of 910 at most)
    assert summary["estimate"]["parameters"]["hx.kht"] == pytest.approx(kht, rel=0.01)
    # pairing: the one candidate on the hot outlet, with the sign of dT/dkht (more transfer, colder)
    pairs = summary["pair"]["pairs"]
    assert [(p["variable"], p["parameter"]) for p in pairs] == [("TI-102", "hx.kht")] and pairs[0]["gain"] < 0.0
    # tracking starts from the spec's 1000 and the compiled box ends within 2 % of the truth on the
    # held-out half hour (the measurement noise moves a tracked kht by about 1 %)
    val = summary["validate"]
    assert val["parameters"]["hx.kht"]["final"] == pytest.approx(kht, rel=0.02)
    assert summary["track"]["parameters"]["hx.kht"]["final"] == pytest.approx(kht, rel=0.02)
    v = val["variables"]["TI-102"]
    assert v["nrmse_tracked"] <= 0.3 * v["nrmse_untracked"]
    # the compiled box and the Python runtime agree within 1 % of the bound range (see test_generate)
    assert val["agreement"] <= 0.01
    for rel in ("report.html", "validate/validation.md", "generated/TwinTracking/TwinTrackingBox.mo"):
        assert (out / rel).is_file(), rel
