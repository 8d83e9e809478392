"""Report of the tracking stage: measured/untracked/tracked per tag, parameters with bounds (and the plant's
true value where known), state-compensation flows, tables and events."""
from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from . import plots
from .document import Document, StageReport, fmt
from .identify import band_paragraph, draw_band, fit_paragraph

if TYPE_CHECKING:
    from ..spec import Spec
    from ..tracking.runtime import TrackingResult


def summary_tables(result: TrackingResult, paired: Mapping[str, str] | None = None) -> Document:
    """The run's tables: fit per tag (paired tags first), parameters, corrections.

    *paired* maps each tracking variable to its parameter. The document's title is empty; :meth:`Document.blocks`
    are what callers use.
    """
    paired = paired or {}
    doc = Document("")
    order = [t for t in result.variables if t in paired] + [t for t in result.variables if t not in paired]
    rows = []
    for tag in order:
        v = result.variables[tag]
        ratio = v.nrmse_tracked / v.nrmse_untracked if v.nrmse_untracked and math.isfinite(v.nrmse_untracked) \
            else math.nan
        rows.append([tag, f"`{paired[tag]}`" if tag in paired else "", fmt(v.nrmse_untracked),
                     fmt(v.nrmse_tracked), fmt(ratio), str(v.samples)])
    doc.table(["tag", "tracked by", "NRMSE untracked", "NRMSE tracked", "ratio", "samples"], rows, align="llrrrr")
    doc.table(["parameter", "final", "min", "max", "lower bound", "upper bound"],
              [[n, fmt(p.final), fmt(p.min), fmt(p.max), fmt(p.lower), fmt(p.upper)]
               for n, p in result.parameters.items()])
    if result.corrections:
        doc.table(["correction (kg/s)", "final", "min", "max"],
                  [[n, fmt(c.final), fmt(c.min), fmt(c.max)] for n, c in result.corrections.items()])
    return doc


def write_track_report(spec: Spec, result: TrackingResult, out: str | os.PathLike[str], *,
                       truth: Mapping[str, float] | None = None) -> StageReport:
    """Write ``tag_<tag>.png``, ``parameter_<name>.png``, ``corrections.png`` and ``summary.md`` into *out*.

    (``result.json`` with the full figures is written by the run itself, into its output directory.)

    Parameters
    ----------
    spec, result
        The spec and what :func:`trackingbox.tracking.runtime.track` returned (its CSV is read).
    truth
        Plant parameter values where known (bench cases), drawn beside the tracked parameters.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plt = plots.pyplot()
    df = pd.read_csv(result.csv)
    hours = df["time"].to_numpy() / 3600.0
    hold = (0.0, float(spec.tracking.hold_until) / 3600.0)
    files: list[Path] = []
    images: list[tuple[Path, str]] = []
    for tag in [c.split(":", 1)[1] for c in df.columns if c.startswith("tracked:")]:
        fig, ax = plt.subplots(figsize=(9, 3.6))
        plots.series(ax, hours, df[f"measured:{tag}"],
                     [plots.Line(df[f"untracked:{tag}"], "untracked twin", plots.UNTRACKED),
                      plots.Line(df[f"tracked:{tag}"], "tracked twin", plots.TRACKED)],
                     ylabel=tag, title=f"{tag}: measured, untracked and tracked", band=hold,
                     band_label="start-up hold")
        files.append(plots.save(fig, out / f"tag_{plots.safe_name(tag)}.png"))
        images.append((files[-1], tag))
    on_hold = df[[c for c in df.columns if c.startswith("mode:")]].eq("hold").any(axis=1).to_numpy()
    for name, p in result.parameters.items():
        fig = plots.parameter(hours, [plots.Line(df[f"parameter:{name}"], "tracked", plots.PYTHON)], name=name,
                              lower=p.lower, upper=p.upper, truth=plots.truth_for(truth, name), hold=on_hold)
        if f"parameter_lo:{name}" in df.columns:  # trackingbox.identify: the tracked parameter's band
            draw_band(fig.axes[0], hours, df[f"parameter_lo:{name}"], df[f"parameter_hi:{name}"])
        files.append(plots.save(fig, out / f"parameter_{plots.safe_name(name)}.png"))
        images.append((files[-1], f"parameter {name}"))
    corr_cols = [c for c in df.columns if c.startswith("correction:")]
    if corr_cols:
        fig, ax = plt.subplots(figsize=(9, 3.2))
        plots.series(ax, hours, None, [plots.Line(df[c], c.split(":", 1)[1], f"C{i}", width=1.0)
                                       for i, c in enumerate(corr_cols)],
                     ylabel="correction flow (kg/s)", title="state compensation")
        files.append(plots.save(fig, out / "corrections.png"))
        images.append((files[-1], "state compensation"))

    doc = Document(f"Tracking run: {Path(spec.path).name}")
    doc.bullets([f"twin: `{Path(spec.twin).name}`, sample time {spec.sample_time:g} s, start-up hold until "
                 f"{spec.tracking.hold_until:g} s",
                 f"metrics over [{result.window[0]:g}, {result.window[1]:g}) s (after the hold; stoppages and "
                 "missing samples excluded); NRMSE = RMSE / measured range",
                 f"{result.steps} rows, {result.simulated_seconds:g} s simulated in {result.seconds:.1f} s wall",
                 f"trajectory: `{result.csv}`"])
    doc.blocks += summary_tables(result, {p.variable: p.parameter for p in spec.pairs}).blocks
    if any(c.startswith("parameter_lo:") for c in df.columns):
        doc.paragraph(band_paragraph())
        fit = fit_paragraph(df)
        if fit:
            doc.paragraph(fit)
    if truth:
        known = {n: truth[n] for n in result.parameters if n in truth}
        if known:
            doc.paragraph("Plant truth (bench case): " + ", ".join(
                f"`{n}` = {v:.6g} (final tracked {result.parameters[n].final:.6g}, "
                f"{100 * (result.parameters[n].final - v) / v:+.2f} %)" if v else f"`{n}` = {v:.6g}"
                for n, v in known.items()))
    if result.events:
        doc.heading("Events")
        doc.bullets([f"t = {e.time:g} s, {e.kind}: {e.message}" for e in result.events[:50]]
                    + ([f"... {len(result.events) - 50} more"] if len(result.events) > 50 else []))
    doc.heading("Plots")
    for path, title in images:
        doc.image(path, title)
    md = doc.write_markdown(out / "summary.md")
    return StageReport(markdown=md, files=(*files, md), document=doc)
