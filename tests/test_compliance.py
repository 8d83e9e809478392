"""The compliance runner (scripts/compliance) on a small fixed sample of the shared suite."""
from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

from trackingbox.compiler.library import model_files
from trackingbox.compiler.source import resolve_source
from trackingbox.compliance import default_suite, discover, location_verdict, main

pytestmark = pytest.mark.compile

SUITE = default_suite()
needs_suite = pytest.mark.skipif(not (SUITE / "package.mo").is_file(),
                                 reason=f"the compliance suite is not at {SUITE} (../shared/modelica-compliance)")

SAMPLE = [
    "ModelicaCompliance.Arrays.Functions.Algebra.Transpose1",     # valid, in the supported subset
    "ModelicaCompliance.Algorithms.When.WhenPriority",            # valid, when-clause (refused)
    "ModelicaCompliance.Algorithms.Assert.AssertNoEval",          # valid, algorithm section (refused)
    "ModelicaCompliance.Algorithms.Assert.AssertError",           # invalid
    "ModelicaCompliance.Components.Declarations.TypeNameAsComponentName.TypeNameAsComponentName",  # nested, invalid
]


@needs_suite
def test_discover_finds_every_test_case():
    # Independent count: files holding a TestCase annotation, and how many say shouldPass = true.
    files = subprocess.run(["grep", "-rl", "--include=*.mo", "shouldPass", str(SUITE)],
                           capture_output=True, text=True, check=True).stdout.split()
    true = subprocess.run(["grep", "-rlE", "--include=*.mo", r"shouldPass *= *true", str(SUITE)],
                          capture_output=True, text=True, check=True).stdout.split()
    models = discover(SUITE)
    assert len(models) == len(files)
    assert sum(m.should_pass for m in models) == len(true)
    assert len({m.name for m in models}) == len(models)
    nested = [m for m in models if m.name.endswith("TypeNameAsComponentName.TypeNameAsComponentName")]
    assert len(nested) == 1 and not nested[0].should_pass


@needs_suite
def test_runner_on_a_sample_keeps_the_invariants(tmp_path, capsys):
    out = tmp_path / "results.jsonl"
    args = ["--suite", str(SUITE), "--out", str(out), "-j", "2", "--timeout", "120"]
    for name in SAMPLE:
        args += ["--match", name]
    assert main(args) == 0
    table = capsys.readouterr().out
    assert "TOTAL" in table and "Algorithms" in table
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    by_model = {r["model"]: r for r in lines}
    assert set(by_model) == set(SAMPLE)  # one line per model, written as they finished
    src = resolve_source(SUITE)
    for r in lines:
        assert r["outcome"] not in ("crashed", "hang"), r
        if r["should_pass"]:
            assert r["outcome"] in ("pass", "refused-construct", "refused-other", "wrong-values", "sim-failed")
        else:
            assert r["outcome"] in ("rejected", "accepted")
        if r["outcome"] == "refused-construct":
            # names a file of the model's own class (or a class it uses) and a line inside that file
            allowed = {str(f) for f in model_files(src, r["model"])}
            assert r["locations"], r
            for file, line in r["locations"]:
                assert file in allowed, (r["model"], file)
                assert 1 <= line <= len(Path(file).read_text().splitlines())
        # every compile-time refusal names a line inside the model's own class (and the construct's line)
        assert location_verdict(r) in (None, "ok"), r
    assert "loc:bad" in table
    assert location_verdict(by_model[SAMPLE[4]]) == "ok"  # rumoca gives no position: the runner's own search
    assert by_model[SAMPLE[0]]["outcome"] == "pass"
    when = by_model[SAMPLE[1]]
    assert when["outcome"] == "refused-construct"
    own = Path(when["file"]).read_text().splitlines()
    file, line = when["locations"][0]
    assert file == when["file"] and re.search(r"\bwhen\b", own[line - 1])
    # --table prints the same table from the results file alone
    assert main(["--table", str(out)]) == 0
    assert capsys.readouterr().out.strip() == table.strip().rsplit("\n", 1)[0].strip()
    # --resume computes nothing again and keeps what is there
    before = out.read_text()
    assert main(args + ["--resume"]) == 0
    assert out.read_text() == before
