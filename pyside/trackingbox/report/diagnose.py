"""Report of the diagnosis stage: where the gap was, what was named, the Modelica diff, the gap shrinking."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..diagnose.residuals import heatmap_matrix
from ..io import write_text_atomic
from . import plots
from .document import Document, StageReport, fmt

if TYPE_CHECKING:
    from ..diagnose.apply import ApplyResult
    from ..diagnose.stage import DiagnosisResult
    from ..spec import Spec


def _hours(periods: list[tuple[float, float]] | tuple[tuple[float, float], ...]) -> str:
    return ", ".join(f"{a / 3600:.1f}-{b / 3600:.1f} h" for a, b in periods) or "-"


def write_diagnose_report(spec: Spec, result: DiagnosisResult, out: str | os.PathLike[str]) -> StageReport:
    """Write ``diagnosis.md``, ``residual_heatmap.png``, ``gap_<tag>.png``, ``patch.diff`` and ``diagnosis.json``.

    Parameters
    ----------
    spec, result
        The spec and what :func:`trackingbox.diagnose.diagnose` found.
    out
        The report folder.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plt = plots.pyplot()
    files: list[Path] = []
    w = result.where
    doc = Document(f"Diagnosis: {Path(spec.path).name}")
    named = result.named
    verdict = {"effect": f"**effect**: `{named.effect}` on `{named.target}`" if named else "**effect**",
               "none": "**none**: the twin explains the data within noise",
               "unexplained": "**unexplained**: a significant residual remains that no effect entry explains"}
    doc.paragraph(f"Verdict: {verdict[result.verdict]} ({result.seconds:.1f} s). The null model is the twin with "
                  f"the spec's candidate parameters fitted on the training window ("
                  + ", ".join(f"`{k}` = {v:.6g}" for k, v in w.null.parameters.items()) + ").")

    doc.heading("Where the twin and the measurements disagree")
    doc.paragraph("Residual = measured - simulated on the scored samples; noise = what the residual is judged "
                  "against: the sensor's white-noise standard deviation (estimated from the measured series' "
                  "second differences) and the spread the measured inputs' own noise causes in the simulated "
                  "output (the null model run again with an independent draw of that noise), in quadrature. "
                  "Trend in tag units per hour; lag = the first-order sensor lag the residual's correlation with "
                  "the output's rate indicates.")
    rows = []
    for tag, res in w.tags.items():
        val = w.validation_tags[tag]
        sensor = getattr(w, "sensor_noise", {}).get(tag, math.nan)
        inputs = getattr(w, "propagated", {}).get(tag, math.nan)
        rows.append([f"`{tag}`", fmt(res.noise), fmt(sensor), fmt(inputs), fmt(res.rms), fmt(res.offset),
                     fmt(res.trend), fmt(res.lag_seconds, ".3g"), fmt(res.conditions_r2, ".2f"), fmt(val.rms),
                     "yes" if tag in w.significant else "no", _hours(res.periods + val.periods)])
    doc.table(["tag", "noise", "sensor", "from inputs", "rms", "offset", "trend /h", "lag s", "inputs R²",
               "valid rms", "significant", "periods"], rows, align="lrrrrrrrrrll")
    if w.corrections:
        doc.paragraph("State compensation: the mean correction flow the null residual would demand "
                      "(gain × mean level residual): "
                      + ", ".join(f"`{t}` {v:.4g}" for t, v in w.corrections.items()) + ".")
    if w.balances:
        doc.table(["balance", "tags", "mean imbalance", "noise", "closes"],
                  [[b.name, ", ".join(f"`{t}`" for t in b.tags), fmt(b.imbalance), fmt(b.noise),
                    "yes" if b.closes else "no (a sensor among its tags is suspect)"] for b in w.balances],
                  align="lllrl")
    tags, cols, values = heatmap_matrix(w)
    finite = values[np.isfinite(values)]
    if finite.size:
        fig = plots.heatmap("normalised residual (block mean of r / noise): training | validation",
                            tags, cols, values, set(), cmap="RdBu_r", center=0.0)
        files.append(plots.save(fig, out / "residual_heatmap.png"))
        doc.image(files[-1], "normalised residual, tag x time")

    doc.heading("Candidates")
    doc.paragraph("Ranked by the BIC gain over the null on training (positive favours the effect); validation gain "
                  "= relative fall of the affected tags' NRMSE on the validation window; noise gain = fall of their "
                  "mean square residual in noise variances. Only a candidate passing every check is named.")
    crow = []
    for c in result.candidates:
        why = "; ".join(result.judgement.reasons.get(f"{c.effect}@{c.target}", [])) or (
            "named" if named is c else "passes (a better one is named)")
        values = ", ".join(f"{k} = {v:.4g}" for k, v in c.values.items())
        crow.append([f"`{c.effect}`", f"`{c.target}`", c.stage, fmt(c.delta_bic, ".4g"),
                     fmt(c.validation_gain, ".3f"), fmt(c.noise_gain, ".3g"), values, why])
    doc.table(["effect", "target", "stage", "ΔBIC", "valid gain", "noise gain", "values", "judgement"], crow,
              align="lllrrrll")

    if result.verdict == "unexplained":
        doc.bullets([f"`{t}`: significant residual at {_hours(p)} that no entry explains"
                     for t, p in result.judgement.unexplained.items()])

    if named is not None:
        doc.heading("What was named")
        expl = result.effects.get(named.effect, "")
        doc.paragraph(f"`{named.effect}` on `{named.target}`: {expl} Fitted: "
                      + ", ".join(f"`{k}` = {v:.6g}" for k, v in named.values.items())
                      + f"; ΔBIC {named.delta_bic:.1f} ({named.stage}).")
        doc.table(["tag", "validation NRMSE twin", "validation NRMSE patched", "change",
                   "residual lag-1 autocorrelation after"],
                  [[f"`{t}`", fmt(named.nrmse_before[t]), fmt(named.nrmse_after[t]),
                    f"{100 * (named.nrmse_after[t] / named.nrmse_before[t] - 1):+.1f} %"
                    if named.nrmse_before[t] else "", fmt(named.whiteness.get(t), ".2f")] for t in named.tags])
        va = w.validation
        for tag in named.tags:
            after = named.validation_residual.get(tag)
            if after is None:
                continue
            patched = va.measured[tag] - after
            fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
            x = va.time / 3600.0
            plots.series(axes[0], x, va.measured[tag],
                         [plots.Line(va.simulated[tag], "twin (null fit)", plots.UNTRACKED),
                          plots.Line(patched, f"patched twin ({named.effect})", plots.TRACKED)],
                         ylabel=tag, title=f"{tag}: validation window", xlabel=None)
            axes[1].plot(x, va.residual(tag), ".", ms=2, color=plots.UNTRACKED, label="residual, twin")
            axes[1].plot(x, after, ".", ms=2, color=plots.TRACKED, label="residual, patched")
            axes[1].axhline(0.0, color="k", lw=0.8)
            axes[1].set_ylabel("measured - simulated")
            axes[1].set_xlabel("time from first sample (h)")
            axes[1].grid(alpha=0.3)
            axes[1].legend(loc="best", fontsize=8)
            files.append(plots.save(fig, out / f"gap_{plots.safe_name(tag)}.png"))
            doc.image(files[-1], f"{tag}: the gap before and after")
    if result.patch is not None:
        doc.heading("The Modelica change")
        doc.paragraph(f"`{result.patch.model}` extends the twin with the named effect"
                      + (f"; compiled: `{result.patch_fmu}`" if result.patch_fmu else "")
                      + (f"; patched spec: `{result.patch_spec}`" if result.patch_spec else "") + ".")
        diff = getattr(result.patch, "diff", "") or result.patch.source
        target = out / "patch.diff"
        write_text_atomic(target, diff)
        files.append(target)
        doc.code(diff, "diff")
    md = doc.write_markdown(out / "diagnosis.md")
    js = out / "diagnosis.json"
    write_text_atomic(js, json.dumps(result.to_json(), indent=2, default=_json_default) + "\n")
    return StageReport(markdown=md, files=(*files, md, js), document=doc)


def _json_default(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return str(value)


def write_apply_report(result: ApplyResult) -> StageReport:
    """Write ``apply.md`` beside ``apply.json``: what each round named, the tracked parameters' errors
    against the plant's truth before and after the patch, the phases' wall times and ``apply.png``."""
    doc = Document("diagnose --apply: the named effects removed from the tracked parameters")
    doc.paragraph("Each round diagnoses the twin, patches it with the named effect and re-estimates, re-pairs "
                  "and re-tracks it over the same data (the effect's parameters held at their joint estimate); "
                  "the unpatched twin went through the same pipeline. Errors are |tracked - plant truth| from "
                  "the settling time on. Stopped: " + (result.stopped or "-") + ".")
    before = result.before
    rows = []
    def shown(name: str, pairs: Any) -> str:  # a candidate no pair drove kept its start
        return name if name in {q for _, q in pairs} else f"{name} (not paired: its start)"

    for name, e in (before.errors.items() if before else ()):
        rows.append(["unpatched", shown(name, before.pairs), fmt(e.max_error), fmt(e.median_error), "-"])
    for r in result.rounds:
        named = r.get("named")
        label = f"round {r['round']}: " + (f"+ {named['effect']}@{named['target']}" if named
                                           else f"nothing named ({r['verdict']})")
        errors = (r.get("retrack") or {}).get("errors", {})
        if not errors:
            rows.append([label, "-", "-", "-", "-"])
        for name, e in errors.items():
            b = before.errors.get(name) if before else None
            ratio = e["max_error"] / b.max_error if b and b.max_error and e["max_error"] is not None else None
            rows.append([label, shown(name, r["retrack"].get("pairs", [])), fmt(e["max_error"]),
                         fmt(e["median_error"]), fmt(ratio)])
    doc.table(["twin", "parameter", "largest error after settling", "median error", "largest / unpatched"], rows)
    kept = [("unpatched", k) for k in (before.kept if before else ())]
    kept += [(f"round {r['round']}", k) for r in result.rounds for k in (r.get("retrack") or {}).get("kept", [])]
    if kept:
        doc.paragraph("Paired although `pair` refused the pair (a parameter the spec tracks in time, "
                      "`[diagnose] varying`: the comparison needs it tracked before and after the patch):")
        doc.bullets([f"{label}: {k['parameter']} on {k['variable']}; pair's reason: {k['refused']}"
                     for label, k in kept])
    phases = []
    if before:
        phases.append(["unpatched"] + [fmt(before.timings.get(k)) for k in ("estimate", "pair", "track")] + ["-"])
    for r in result.rounds:
        t = (r.get("retrack") or {}).get("timings", {})
        phases.append([f"round {r['round']}"] + [fmt(t.get(k)) for k in ("estimate", "pair", "track")]
                      + [fmt(r.get("timings", {}).get("diagnose"))])
    doc.table(["twin", "estimate (s)", "pair (s)", "track (s)", "diagnose (s)"], phases)
    files = [result.out / "apply.json"]
    if result.plot is not None:
        doc.image(result.plot, "tracked parameters before and after the patch")
        files.append(result.plot)
    md = doc.write_markdown(result.out / "apply.md")
    return StageReport(markdown=md, files=(*files, md), document=doc)
