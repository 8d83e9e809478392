"""Report of what the data determine: the identifiability check, the intervals and the correlation matrix.

:func:`uncertainty_section` adds the estimate's intervals (a chart: each
parameter's interval within its bounds, the plant's truth where a bench case
knows it; the determined combinations relative to their estimates) and the
correlation matrix to a stage's document (the estimation report calls it);
:func:`write_identify_report` is ``trackingbox identify --report DIR``.
"""
from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..identify.bands import LEVEL as BAND_LEVEL
from ..identify.intervals import NONLINEARITY_TOLERANCE
from ..io import write_text_atomic
from . import plots
from .document import Document, StageReport


def interval_figure(uncertainty: Any, bounds: Mapping[str, tuple[float, float]],
                    truth: Mapping[str, float] | None = None) -> Any:
    """Each parameter's interval as a share of its bounds (left), each determined combination's relative
    to its estimate (right, if any); the estimate as a dot, the truth (where known) as a red cross."""
    plt = plots.pyplot()
    params = list(uncertainty.parameters)
    combos = list(uncertainty.combinations)
    ncols = 2 if combos else 1
    height = max(2.2, 0.45 * max(len(params), len(combos)) + 1.2)
    fig, axes = plt.subplots(1, ncols, figsize=(5.5 * ncols, height), squeeze=False)
    ax = axes[0][0]
    for i, iv in enumerate(params):
        lo, hi = bounds[iv.name]
        span = hi - lo

        def frac(v: float) -> float:
            return (v - lo) / span

        y = len(params) - 1 - i
        ax.plot([0, 1], [y, y], color="0.85", lw=6, solid_capstyle="butt")
        if iv.determined and iv.lower is not None and iv.upper is not None:
            ax.plot([frac(iv.lower), frac(iv.upper)], [y, y], color=plots.TRACKED, lw=3,
                    label=f"{100 * iv.level:g} % interval" if i == 0 else None)
        else:
            ax.text(0.5, y + 0.18, "not determined", ha="center", fontsize=8, color="0.35")
        ax.plot(frac(iv.estimate), y, "o", color="k", ms=4, label="estimate" if i == 0 else None)
        t = plots.truth_for(truth, iv.name)
        if t is not None and math.isfinite(t):
            ax.plot(frac(t), y, "x", color=plots.TRUTH, ms=8, mew=2, label="plant truth" if i == 0 else None)
    ax.set_yticks(range(len(params)), [iv.name for iv in reversed(params)], fontsize=8)
    ax.set_xlim(-0.02, 1.02)
    ax.set_xlabel("position within the bounds (0: min, 1: max)")
    ax.set_title("parameters", fontsize=10, loc="left")
    ax.grid(alpha=0.3, axis="x")
    ax.legend(loc="best", fontsize=7)
    if combos:
        ax = axes[0][1]
        for i, iv in enumerate(combos):
            y = len(combos) - 1 - i
            if iv.lower is not None and iv.upper is not None:
                ax.plot([100 * (iv.lower / iv.estimate - 1), 100 * (iv.upper / iv.estimate - 1)], [y, y],
                        color=plots.TRACKED, lw=3)
            ax.plot(0.0, y, "o", color="k", ms=4)
            t = (truth or {}).get(iv.name)
            if t is not None:
                ax.plot(100 * (t / iv.estimate - 1), y, "x", color=plots.TRUTH, ms=8, mew=2)
        ax.set_yticks(range(len(combos)), [iv.name for iv in reversed(combos)], fontsize=8)
        ax.set_xlabel("relative to the estimate (%)")
        ax.set_title("determined combinations", fontsize=10, loc="left")
        ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    return fig


def correlation_figure(names: Any, correlation: Any, title: str) -> Any:
    """The correlation matrix as a heat map (-1 blue, +1 red)."""
    c = np.asarray(correlation, dtype=float)
    strong = {(a, b) for i, a in enumerate(names) for j, b in enumerate(names) if i != j and abs(c[i, j]) > 0.95}
    return plots.heatmap(title, list(names), list(names), c, strong, cmap="RdBu_r", center=0.0)


def uncertainty_section(doc: Document, uncertainty: Any, bounds: Mapping[str, tuple[float, float]], out: Path,
                        truth: Mapping[str, float] | None = None) -> list[Path]:
    """Add the intervals (table and chart), the determined combinations, the findings and the
    correlation matrix to *doc*; returns the PNG files written into *out*."""
    files: list[Path] = []
    doc.heading("What the data determine")
    for f in uncertainty.findings:
        doc.paragraph(f.message)
    header = ["parameter", "estimate", f"{100 * uncertainty.level:g} % interval", "method", "t dof",
              "effective samples"] + (["plant truth", "covered"] if truth else [])
    rows = []
    for iv in list(uncertainty.parameters) + list(uncertainty.combinations):
        t = (truth or {}).get(iv.name)
        cov = iv.covers(t) if t is not None else None
        rows.append([f"`{iv.name}`", f"{iv.estimate:.6g}",
                     f"[{iv.lower:.6g}, {iv.upper:.6g}]" if iv.determined else iv.note,
                     iv.method, f"{iv.dof:.0f}" if math.isfinite(iv.dof) else "",
                     f"{iv.effective_samples:.0f}" if math.isfinite(iv.effective_samples) else ""]
                    + ([f"{t:.6g}" if t is not None else "", "" if cov is None else ("yes" if cov else "NO")]
                       if truth else []))
    doc.table(header, rows)
    for iv in list(uncertainty.parameters) + list(uncertainty.combinations):
        if iv.determined and iv.note:
            doc.paragraph(f"`{iv.name}`: {iv.note}.")
    doc.paragraph(
        "Intervals: linearised from the cost's curvature, with each tag's noise and the residuals' autocorrelation "
        "taken from the residuals (a sandwich covariance whose long-run part is an equal-weighted cosine estimate; "
        "Student t on its terms); profile likelihood where the cost at an end of the linearised interval is off its "
        f"quadratic prediction by more than {100 * NONLINEARITY_TOLERANCE:g} %. Residuals per tag: "
        + "; ".join(f"`{t}` RMS {n.rms:.3g}, lag-1 autocorrelation {n.lag1:.2f}, {n.effective_samples:.0f} effective "
                    f"of {n.samples} samples" for t, n in uncertainty.noise.items()) + ".")
    misfit = getattr(uncertainty, "lack_of_fit", None)
    if misfit is not None:
        doc.paragraph(misfit.message() or "Fit at the estimate: every tag's residual lies within its noise (diagnose's "
                      "test on the training and validation windows), the condition the intervals rest on.")
    fig = interval_figure(uncertainty, bounds, truth)
    files.append(plots.save(fig, out / "intervals.png"))
    doc.image(files[-1], "confidence intervals")
    if len(uncertainty.names) > 1:
        fig = correlation_figure(uncertainty.names, uncertainty.correlation,
                                 "correlation of the estimates (scaled parameters)")
        files.append(plots.save(fig, out / "correlation.png"))
        doc.image(files[-1], "correlation matrix")
    return files


def draw_band(ax: Any, hours: Any, lower: Any, upper: Any) -> None:
    """A tracked parameter's band (``parameter_lo:``/``parameter_hi:`` columns) as a shaded area on *ax*."""
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    ok = np.isfinite(lo) & np.isfinite(hi)
    if ok.any():
        ax.fill_between(np.asarray(hours, dtype=float), lo, hi, where=ok, color=plots.PYTHON, alpha=0.25, lw=0,
                        label=f"{100 * BAND_LEVEL:g} % band", zorder=1)
        ax.legend(loc="best", fontsize=8)


def band_paragraph() -> str:
    """How the tracked parameters' bands are made, for the tracking report."""
    return (f"Bands (shaded; CSV columns `parameter_lo:<name>`, `parameter_hi:<name>`): {100 * BAND_LEVEL:g} % "
            "from the tag's noise fed through the parameter controller (the loop linearised from the pair's gain, "
            "time constant and PI settings; the noise's autocovariance from the tracked error's fast part), the "
            "start value's interval (the spec's `interval`, else the bounds) fading as the loop converges, and the "
            "loop's lag behind the parameter's own trend (and the time on hold). Empty until an hour of tracked "
            "error has been seen. What the twin's structure gets wrong is in them only as far as the tags no pair "
            "tracks show it: where the `lack_of_fit` column flags such a tag, the band reaches the value of the "
            "parameter that tag implies.")


def fit_paragraph(df: Any) -> str | None:
    """The lack-of-fit flag of a tracking CSV (:mod:`trackingbox.identify.bands`) in words; None without it."""
    if "lack_of_fit" not in df.columns:
        return None
    f = np.asarray(df["lack_of_fit"], dtype=float)
    known = np.isfinite(f)
    if not known.any():
        return "Lack of fit: not known yet (it needs an hour of tracked error and two hours of the untracked tags)."
    flagged = known & (f >= 1.0)
    share = float(flagged.sum() / known.sum())
    head = (f"Lack of fit: the tags no pair tracks disagree with the twin beyond their noise in {100 * share:.1f} % "
            f"of the rows where it is known (the CSV's `lack_of_fit` >= 1, largest {float(np.nanmax(f)):.3g}).")
    if flagged.any():
        return head + (" **There a tracked parameter may be absorbing an effect the twin lacks**: its band "
                       "reaches the values the flagged tags imply (where their gains were measured), which cover "
                       "that model error only as far as those tags show it (find the effect with `diagnose`).")
    return head + " The bands' noise and start terms are all there is to it."




def write_identify_report(spec: Any, result: Any, out: str | os.PathLike[str]) -> StageReport:
    """``identify.md``, ``correlation.png`` and ``identify.json`` into *out*."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    doc = Document(f"What the data determine: {Path(spec.path).name}")
    method, reason = result.sensitivities
    doc.paragraph(f"Output sensitivities on the training window, {method}"
                  + (f" ({reason})" if reason and reason != "requested" else "")
                  + "; columns scaled to relative changes (log-parameters) where the bounds are positive, else to "
                    "the bound range; each tag's rows divided by its sensor noise: "
                  + "; ".join(f"`{t}` {s:.3g} ({src})" for t, (s, src) in result.noise.items()) + ".")
    rows = [[p.label, str(p.rank), str(p.determined), ", ".join(p.undetermined_parameters) or "-",
             ", ".join(f"{s:.3g}" for s in p.singular_values) or p.error] for p in result.points]
    doc.table(["point", "rank", "determined directions", "in undetermined directions", "singular values"], rows)
    for message in result.messages() or ["Every parameter is determined on its own."]:
        doc.paragraph(message)
    files: list[Path] = []
    if len(result.names) > 1:
        fig = correlation_figure(result.names, result.correlation, "correlation at the start values")
        files.append(plots.save(fig, out / "correlation.png"))
        doc.image(files[-1], "correlation matrix")
    md = doc.write_markdown(out / "identify.md")
    target = out / "identify.json"
    write_text_atomic(target, json.dumps(result.to_json(), indent=2) + "\n")
    return StageReport(markdown=md, files=(*files, md, target), document=doc)
