"""The report package's shared pieces, the commands' progress line and the pairing stage's spec entries.

Expected texts are written out by hand; nothing is compared with the code's own output.
"""
from __future__ import annotations

import base64
import io
import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from trackingbox.report import Document, write_html
from trackingbox.report import plots

PNG_1X1 = base64.b64decode("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNk+M9QDwADhgGAWjR9awAAAABJRU5ErkJggg==")


def _doc(tmp_path: Path) -> Document:
    (tmp_path / "plots").mkdir()
    (tmp_path / "plots" / "a.png").write_bytes(PNG_1X1)
    doc = Document("Run <1>")
    doc.paragraph("kht went `hx.kht` < **900**, see [track](track/summary.md)")
    doc.heading("Fit")
    doc.table(["tag", "NRMSE"], [["TI-102", "0.01"], ["TI-202", "-"]])
    doc.bullets(["one", "two"])
    doc.bullets([])  # nothing
    doc.image(tmp_path / "plots" / "a.png", "a plot")
    return doc


def test_markdown_text(tmp_path: Path) -> None:
    md = _doc(tmp_path).write_markdown(tmp_path / "report.md")
    assert md.read_text() == (
        "# Run <1>\n\n"
        "kht went `hx.kht` < **900**, see [track](track/summary.md)\n\n"
        "## Fit\n\n"
        "| tag | NRMSE |\n|---|---:|\n| TI-102 | 0.01 |\n| TI-202 | - |\n\n"
        "- one\n- two\n\n"
        "![a plot](plots/a.png)\n")


def test_html_page_is_self_contained(tmp_path: Path) -> None:
    page = write_html(tmp_path / "out" / "page.html", "demo", [_doc(tmp_path)]).read_text()
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert "<h1>Run &lt;1&gt;</h1>" in page
    assert ('<p>kht went <code>hx.kht</code> &lt; <b>900</b>, see <a href="track/summary.md">track</a></p>'
            in page)
    assert '<td>TI-102</td><td class="num">0.01</td>' in page
    [data] = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert base64.b64decode(data) == PNG_1X1  # the plot itself, not a link to it
    assert "a.png" not in page


def test_table_align_must_match_columns() -> None:
    with pytest.raises(ValueError, match="2 letters for 3 columns"):
        Document("x").table(["a", "b", "c"], [], align="lr")


def test_extend_moves_headings_down() -> None:
    inner = Document("Stage")
    inner.heading("Part")
    outer = Document("All")
    outer.extend(inner)
    assert outer.markdown() == "# All\n\n## Stage\n\n### Part\n"


def test_parameter_plot_shows_truth_and_bounds() -> None:
    x = np.linspace(0.0, 2.0, 5)
    fig = plots.parameter(x, [plots.Line([1000, 950, 920, 912, 910], "tracked")], name="hx.kht",
                          lower=500.0, upper=1500.0, truth=910.0)
    ax = fig.axes[0]
    flat = {ln.get_label(): set(np.asarray(ln.get_ydata(), dtype=float)) for ln in ax.get_lines()}
    assert flat["plant truth (910)"] == {910.0}
    assert flat["bounds"] == {500.0}
    assert "tracked" in flat
    plots.pyplot().close(fig)
    fig = plots.parameter(x, [plots.Line(x, "tracked")], name="p", lower=0.0, upper=1.0, truth=None)
    assert not any(ln.get_label().startswith("plant truth") for ln in fig.axes[0].get_lines())
    plots.pyplot().close(fig)


def test_progress_lines_on_a_log_stream(monkeypatch: pytest.MonkeyPatch) -> None:
    from trackingbox.commands import _progress

    clock = iter([0.0, 0.0, 1.0, 2.0, 7.0, 8.0, 9.0])
    monkeypatch.setattr(_progress.time, "perf_counter", lambda: next(clock))
    stream = io.StringIO()
    p = _progress.Progress(every=5.0, stream=stream)     # t0 = 0
    count = p.counter("tracking", unit="row")
    count(1, 10)    # t = 0: new stage -> shown
    count(2, 10)    # t = 1: within 5 s -> not shown
    count(3, 10)    # t = 2: not shown
    count(6, 10)    # t = 7: shown; 5 rows in 7 s since the stage began -> 4 rows left ~ 5.6 s
    count(7, 10)    # t = 8: not shown
    count(10, 10)   # t = 9: the end -> shown
    assert stream.getvalue().splitlines() == [
        "tracking: row 1/10 (0 s elapsed)",
        "tracking: row 6/10 (7 s elapsed, at most ~6 s left)",
        "tracking: row 10/10 (9 s elapsed)",
    ]


def test_progress_rate_leaves_out_the_start_up_and_restarts_with_a_count(monkeypatch: pytest.MonkeyPatch) -> None:
    # the demo's estimate read "at most ~7 h 56 min left" after the first two runs of a parallel batch
    # (their time held the workers' start-up), and pair's Sobol re-run "~50 h 44 min" (its count began
    # again under the same stage name, against the whole stage's time): worked out by hand below
    from trackingbox.commands import _progress

    clock = iter([0.0, 0.0, 60.0, 70.0, 80.0, 90.0, 100.0, 110.0])
    monkeypatch.setattr(_progress.time, "perf_counter", lambda: next(clock))
    stream = io.StringIO()
    p = _progress.Progress(every=5.0, stream=stream)     # t0 = 0
    count = p.counter("runs")
    count(0, 100)   # t = 0: the batch starts
    count(2, 100)   # t = 60: the first two runs, after 60 s of start-up: no rate yet
    count(4, 100)   # t = 70: two runs in 10 s since then -> 96 left ~ 480 s (not 96 x 60/4 = 24 min)
    count(6, 100)   # t = 80: 4 in 20 s -> 94 left ~ 470 s
    count(1, 100)   # t = 90: the count starts again: a new stage line, no rate
    count(3, 100)   # t = 100: 2 in 10 s since the restart -> 97 left ~ 485 s
    count(100, 100)  # t = 110
    assert stream.getvalue().splitlines() == [
        "runs: 0/100 (0 s elapsed)",
        "runs: 2/100 (1 min 00 s elapsed)",
        "runs: 4/100 (1 min 10 s elapsed, at most ~8 min 00 s left)",
        "runs: 6/100 (1 min 20 s elapsed, at most ~7 min 50 s left)",
        "runs: 1/100 (1 min 30 s elapsed)",
        "runs: 3/100 (1 min 40 s elapsed, at most ~8 min 05 s left)",
        "runs: 100/100 (1 min 50 s elapsed)",
    ]

    # the demo's refinement: one serial run, then parallel batches of 32; a budget's last runs past it
    clock = iter([0.0, 0.0, 90.0, 170.0, 260.0])
    stream = io.StringIO()
    p = _progress.Progress(every=5.0, stream=stream)
    count = p.counter("refinement")
    count(1, 320)    # t = 0
    count(2, 320)    # t = 90: 1 run since the first line, under 2 % of the 319 left: no estimate
    count(34, 320)   # t = 170: 33 in 170 s -> 286 left ~ 1473 s
    count(322, 320)  # t = 260: past the budget: shown as done, not "322/320"
    assert stream.getvalue().splitlines() == [
        "refinement: 1/320 (0 s elapsed)",
        "refinement: 2/320 (1 min 30 s elapsed)",
        "refinement: 34/320 (2 min 50 s elapsed, at most ~24 min 33 s left)",
        "refinement: 322/322 (4 min 20 s elapsed)",
    ]


def test_spec_pairs_keeps_tuning_of_existing_pairs(tmp_path: Path) -> None:
    from trackingbox.analysis.pair_stage import spec_pairs
    from trackingbox.spec import PairSpec

    old = PairSpec(variable="TI", parameter="k", gain=1.0, time_constant=5.0, lambda_=2.5, kp=0.3, ti=40.0)
    spec = SimpleNamespace(pairs=(old,), pairing=SimpleNamespace(closed_loop=None))
    chosen = (SimpleNamespace(variable="TI", parameter="k", gain=-0.02, time_constant=120.0),
              SimpleNamespace(variable="LI", parameter="q", gain=3.0, time_constant=math.nan))
    result = SimpleNamespace(pairing=SimpleNamespace(pairs=chosen), step_settings=SimpleNamespace(interval=10.0),
                             settings=SimpleNamespace(closed_loop=None))
    kept, new = spec_pairs(spec, result)  # type: ignore[arg-type]
    assert (kept.gain, kept.time_constant, kept.lambda_, kept.kp, kept.ti) == (-0.02, 120.0, 2.5, 0.3, 40.0)
    # a new pair: lambda 1; no measurable time constant -> the step interval
    assert (new.variable, new.parameter, new.gain, new.time_constant, new.lambda_) == ("LI", "q", 3.0, 10.0, 1.0)
    # a closed-loop time constant (the spec's [pairing] closed_loop) sets a new pair's lambda to reach it:
    # 600 s over the 10 s interval -> 60; an existing pair keeps its own tuning
    spec.pairing.closed_loop = 600.0
    kept, new = spec_pairs(spec, result)  # type: ignore[arg-type]
    assert (kept.lambda_, new.lambda_) == (2.5, 60.0)
    # the command's value (the result's settings) wins over the spec's; below the time constant lambda stays 1
    result.settings.closed_loop = 5.0
    assert spec_pairs(spec, result)[1].lambda_ == 1.0  # type: ignore[arg-type]


def test_demo_overview_puts_plant_truth_beside_tracked_values(tmp_path: Path) -> None:
    from trackingbox.demo import Run, summary_document

    run = Run(out=tmp_path, bench="heat-exchanger", seed=0, truth={"hx.kht": 910.0}, summary={
        "track": {"variables": {"TI-102": {"nrmse_untracked": 0.1453, "nrmse_tracked": 0.01087}},
                  "parameters": {"hx.kht": {"final": 902.457, "min": 891.934, "max": 1000.0}}, "seconds": 1.0}})
    md = summary_document(run, 12.0).markdown()
    assert "## Tracking in Python" in md
    assert "| TI-102 | 0.1453 | 0.01087 |" in md
    assert "| hx.kht | 902.457 | 891.934 | 1000 | 910 |" in md
    assert "## Compiled TrackingBox" not in md  # a step that did not run has no section
