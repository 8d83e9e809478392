"""Report of the validation stage: the tracked FMU against the twin and the Python runtime."""
from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from ..generate.filters import modelica_name
from ..io import atomic_path
from . import plots
from .document import Document, StageReport, fmt

if TYPE_CHECKING:
    from ..spec import Spec
    from ..validate import ValidationResult


def write_validate_report(spec: Spec, result: ValidationResult, fmu: str | os.PathLike[str],
                          out: str | os.PathLike[str], *,
                          truth: Mapping[str, float] | None = None) -> StageReport:
    """Write ``variable_<tag>.png``, ``parameter_<name>.png``, ``validation.csv`` and ``validation.md``.

    Parameters
    ----------
    spec, result
        The spec and what :func:`trackingbox.validate.validate` returned.
    fmu
        The tracked FMU that was validated (named in the report).
    truth
        Plant parameter values where known (bench cases), drawn beside the tracked parameters.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plt = plots.pyplot()
    s = result.series
    hours = s["time"].to_numpy() / 3600.0
    window = (result.window[0] / 3600.0, result.window[1] / 3600.0)
    files: list[Path] = []
    images: list[tuple[Path, str]] = []
    for tag in result.variables:
        fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, height_ratios=[2, 1])
        plots.series(ax, hours, s[f"measured:{tag}"],
                     [plots.Line(s[f"untracked:{tag}"], "twin (untracked)", plots.UNTRACKED, width=1.0),
                      plots.Line(s[f"python:{tag}"], "tracked (Python runtime)", plots.PYTHON, "--", 1.0),
                      plots.Line(s[f"tracked:{tag}"], "tracked (Modelica box, FMU)", plots.TRACKED)],
                     ylabel=tag, band=window, band_label="validation window", xlabel=None)
        plots.series(ax2, hours, None,
                     [plots.Line(s[f"untracked:{tag}"] - s[f"measured:{tag}"], "untracked", plots.UNTRACKED,
                                 width=0.8),
                      plots.Line(s[f"tracked:{tag}"] - s[f"measured:{tag}"], "tracked (FMU)", plots.TRACKED,
                                 width=0.8)], ylabel="residual")
        ax2.axhline(0.0, color="k", lw=0.5)
        files.append(plots.save(fig, out / f"variable_{modelica_name(tag)}.png"))
        images.append((files[-1], f"{tag}: measured, twin and tracked; residuals"))
    for name, p in result.parameters.items():
        fig = plots.parameter(hours, [plots.Line(s[f"python:{name}"], "Python runtime", plots.PYTHON, "--", 1.0),
                                      plots.Line(s[f"modelica:{name}"], "Modelica box (FMU)", plots.TRACKED)],
                              name=name, lower=p.lower, upper=p.upper, truth=plots.truth_for(truth, name),
                              band=window, band_label="validation window", title=f"{name}: trajectory")
        files.append(plots.save(fig, out / f"parameter_{modelica_name(name)}.png"))
        images.append((files[-1], f"{name}: trajectory"))
    csv = out / "validation.csv"
    with atomic_path(csv) as tmp:
        s.to_csv(tmp, index=False)

    doc = Document("Validation of the tracked model")
    doc.bullets([f"tracked FMU: `{Path(fmu).name}`", f"spec: `{Path(spec.path).name}`",
                 f"validation window: {result.window[0]:g} s to {result.window[1]:g} s (runs start at the first "
                 "sample)",
                 f"agreement Modelica box vs Python runtime (max |Δp| / (max − min)): **{fmt(result.agreement)}**"])
    doc.heading("Tracking variables (NRMSE on the validation window)")
    doc.table(["tag", "untracked", "tracked (FMU)", "tracked (Python)", "converged at (s)", "band"],
              [[tag, fmt(v.nrmse_untracked), fmt(v.nrmse_tracked), fmt(v.nrmse_python),
                fmt(v.converged_at, ".0f") if v.converged_at is not None else "not converged", fmt(v.band)]
               for tag, v in result.variables.items()])
    doc.heading("Tracking parameters")
    header = ["parameter", "final (FMU)", "final (Python)", "min", "max", "bounds", "within", "agreement"]
    rows = [[name, fmt(p.final), fmt(p.final_python), fmt(p.min), fmt(p.max), f"[{p.lower:g}, {p.upper:g}]",
             "yes" if p.within_bounds else "NO", fmt(p.agreement)] for name, p in result.parameters.items()]
    if truth:
        header.append("plant truth")
        rows = [r + [fmt(plots.truth_for(truth, r[0]), ".6g")] for r in rows]
    doc.table(header, rows, align="lrrrrllr" + ("r" if truth else ""))
    doc.heading("Plots")
    for path, title in images:
        doc.image(path, title)
    md = doc.write_markdown(out / "validation.md")
    return StageReport(markdown=md, files=(*files, csv, md), document=doc)
