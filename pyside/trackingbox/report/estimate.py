"""Report of the estimation stage: fit plots per tag, convergence trace, parameter table."""
from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from ..estimation import fit_series
from ..io import write_text_atomic
from . import plots
from .document import Document, StageReport, fmt
from .identify import uncertainty_section

if TYPE_CHECKING:
    from ..estimation import EstimationResult
    from ..spec import Spec


def write_estimate_report(spec: Spec, result: EstimationResult, out: str | os.PathLike[str], *,
                          warmup: float | None = None, truth: Mapping[str, float] | None = None) -> StageReport:
    """Write ``fit_<tag>.png``, ``convergence.png``, ``parameters.md`` and ``result.json`` into *out*.

    Parameters
    ----------
    spec, result
        The spec and what :func:`trackingbox.estimation.estimate` found.
    warmup
        The warm-up the estimation used (for the fit plots' simulations).
    truth
        Plant parameter values where known (bench cases): an extra table column.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plt = plots.pyplot()
    files: list[Path] = []
    doc = Document(f"Parameter estimation: {Path(spec.path).name}")
    note = result.warmup_note()
    doc.paragraph(f"Twin `{Path(spec.twin).name}`, {result.evaluations} simulations in {result.seconds:.1f} s, "
                  f"unscored warm-up of {result.warmup:g} s before each window through the measured history"
                  + (f"; {note}." if note else "."))
    header = ["parameter", "start", "estimate", "min", "max", "at bound"] + (["plant truth"] if truth else [])
    rows = []
    for name, value in result.parameters.items():
        lo, hi = result.bounds[name]
        tol = 1e-6 * (hi - lo)
        at = "min" if value - lo <= tol else "max" if hi - value <= tol else ""
        row = [f"`{name}`", f"{result.initial[name]:.6g}", f"{value:.6g}", f"{lo:.6g}", f"{hi:.6g}", at]
        rows.append(row + ([fmt(plots.truth_for(truth, name), ".6g")] if truth else []))
    doc.table(header, rows, align="lrrrrl" + ("r" if truth else ""))
    doc.paragraph("NRMSE = RMSE / (max - min of the measured tag over the window's valid samples).")
    rows = []
    for tag, v in result.validation_nrmse.items():
        v0 = result.validation_nrmse_initial[tag]
        change = f"{100.0 * (v - v0) / v0:+.1f} %" if v0 > 0 else ""
        rows.append([f"`{tag}`", f"{result.training_nrmse[tag]:.4g}", f"{v:.4g}", f"{v0:.4g}", change])
    doc.table(["tag", "training", "validation", "validation at start values", "change"], rows)

    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.semilogy(range(len(result.history)), result.history, "o-", ms=3)
    ax.set_xlabel("generation (0: start values; last point: after refinement)")
    ax.set_ylabel("best training cost (mean NRMSE)")
    ax.grid(alpha=0.3, which="both")
    files.append(plots.save(fig, out / "convergence.png"))
    doc.image(files[-1], "convergence")
    if getattr(result, "uncertainty", None) is not None:  # trackingbox.identify: intervals, correlation
        files += uncertainty_section(doc, result.uncertainty, result.bounds, out, truth)

    series = fit_series(spec, {"initial": result.initial, "estimated": result.parameters}, warmup=warmup)
    for tag in spec.outputs:
        fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
        for ax, (window, frame) in zip(axes, series.items()):
            nr = (result.training_nrmse if window == "training" else result.validation_nrmse)[tag]
            plots.series(ax, frame["time"] / 3600.0, frame[tag],
                         [plots.Line(frame[f"{tag}:initial"], "start values", plots.UNTRACKED),
                          plots.Line(frame[f"{tag}:estimated"], "estimate", plots.TRACKED)],
                         ylabel=f"{tag} ({spec.outputs[tag]})" if window == "training" else "",
                         title=f"{tag}: {window} (NRMSE {nr:.3g})", xlabel="time from first sample (h)")
        files.append(plots.save(fig, out / f"fit_{plots.safe_name(tag)}.png"))
        doc.image(files[-1], tag)
    md = doc.write_markdown(out / "parameters.md")
    target = out / "result.json"
    write_text_atomic(target, json.dumps({**result.to_json(), "history": list(result.history)}, indent=2) + "\n")
    return StageReport(markdown=md, files=(*files, md, target), document=doc)
