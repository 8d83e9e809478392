"""Report of the pairing stage: RGA and gain heatmaps (chosen pairs boxed), data checks, tables."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..io import write_text_atomic
from . import plots
from .document import Document, StageReport, fmt

if TYPE_CHECKING:
    from ..analysis.pair_stage import PairingResult
    from ..spec import Spec


def _matrix_rows(variables: tuple[str, ...], values: np.ndarray, spec: str) -> list[list[str]]:
    return [[v, *(fmt(float(x), spec) for x in values[i])] for i, v in enumerate(variables)]


def write_pair_report(spec: Spec, result: PairingResult, out: str | os.PathLike[str]) -> StageReport:
    """Write ``rga.png``, ``gains_scaled.png`` (``sobol_total.png``), ``pairing.md`` and ``pairing.json``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    st, pairing, sob, agr, s = (result.steptest, result.pairing, result.sobol, result.agreement,
                                result.step_settings)
    chosen = {(p.variable, p.parameter) for p in pairing.pairs}
    files = [plots.save(plots.heatmap("relative gain array (boxed: chosen pairs)", st.variables, st.parameters,
                                      pairing.rga, chosen, cmap="RdBu_r", center=1.0), out / "rga.png"),
             plots.save(plots.heatmap("scaled steady-state gains (range-normalised)", st.variables,
                                      st.parameters, pairing.scaled_gains, chosen, cmap="PuOr", center=0.0),
                        out / "gains_scaled.png")]
    if sob is not None:
        files.append(plots.save(plots.heatmap("Sobol total-effect indices", sob.variables, sob.parameters,
                                              sob.total, chosen, cmap="viridis"), out / "sobol_total.png"))
    doc = Document(f"Pairing: {Path(spec.path).name}")
    frozen = f" ({', '.join(f'`{n}` = {v:g}' for n, v in s.freeze)})" if s.freeze else " (no freeze input given)"
    text = (f"Twin `{Path(spec.twin).name}`; inputs held at "
            + ", ".join(f"`{k}` = {v:.4g}" for k, v in result.operating_point.items())
            + f". Controllers frozen at t = {st.freeze_time:g} s{frozen}; parameters stepped by "
            f"{'+/-' if s.two_sided else '+'}{100 * s.step:g} % of their bound range at t = {st.step_time:g} s. "
            f"Settle rule: change below {s.tolerance:g} x range over {s.window:g} s. "
            f"{st.runs} step-test runs in {st.seconds:.1f} s.")
    if result.second_point is not None:
        at2, op2 = result.second_point
        text += (f" Repeated at a second operating point (the hour from t = {at2:g} s: "
                 + ", ".join(f"`{k}` = {v:.4g}" for k, v in op2.items()) + "); each pair's gain is the larger "
                 "of the two.")
    doc.paragraph(text)
    doc.heading("Chosen pairs")
    doc.table(["variable", "parameter", "lambda", "gain", "time constant (s)"],
              [[p.variable, p.parameter, f"{p.lambda_:.3f}", f"{p.gain:.4g}", f"{p.time_constant:.4g}"]
               for p in pairing.pairs], align="llrrr")
    doc.paragraph(f"Condition number of the scaled gain matrix: {pairing.condition_number:.4g}; of the chosen "
                  f"pairs: {pairing.pairs_condition_number:.4g}.")
    if pairing.checks is not None:
        c = pairing.checks
        doc.heading("Data checks")
        doc.paragraph("The twin ran untracked over the training window with the measured inputs. Noise = robust "
                      "standard deviation of the measurement's first differences / sqrt(2). Thresholds: "
                      f"untracked RMS error at least {c.noise_ratio:g} x noise; the parameter's remaining range "
                      f"closes at least {c.min_reach:g} x the mean offset; predicted tracked/untracked RMS ratio "
                      f"(all pairs together, first-order loops, parameters clipped) at most {c.max_ratio:g}. "
                      f"Gains: {result.check_rule}.")
        doc.table(["variable", "noise", "mean offset", "RMS error", "RMS / noise"],
                  [[o.variable, fmt(o.noise, ".3g"), fmt(o.mean, ".3g"), fmt(o.rms, ".3g"),
                    fmt(o.noise_ratio, ".3g")] for o in pairing.offsets])
        doc.table(["pair", "predicted ratio", "time at a bound", "closed loop (s)"],
                  [[f"{p.variable} / {p.parameter}", fmt(p.predicted_ratio, ".2f"), fmt(100 * p.at_bound, ".0f")
                    + " %", fmt(p.closed_loop, ".0f")] for p in pairing.pairs])
        if pairing.rejected:
            doc.paragraph("Pairs rejected by the prediction:")
            doc.bullets([f"{v} / {p}: {r}" for v, p, r in pairing.rejected])
    if pairing.block is not None and pairing.block.parameters:
        b = pairing.block
        doc.heading("Pairing per unit")
        doc.paragraph("The parameters of the spec's `[pairing] units` pair with their own unit's tags, chosen so "
                      "that the relative gain array of this square block is closest to the identity (RGA number "
                      f"sum |Lambda - I| = {b.number:.3g}); the other parameters pair on the whole matrix's.")
        doc.table(["", *(st.parameters[j] for j in b.parameters)],
                  [[st.variables[i], *(f"{x:.3g}" for x in row)] for i, row in zip(b.tags, b.rga)])
    if pairing.left_out:
        doc.heading("Left out")
        doc.bullets([f"`{n}`: {r}" for n, r in pairing.left_out])
    if result.warnings:
        doc.heading("Warnings")
        doc.bullets(list(result.warnings))
    doc.heading("Relative gain array")
    doc.image(files[0], "RGA")
    doc.table(["", *st.parameters], _matrix_rows(st.variables, pairing.rga, ".3g"))
    doc.heading("Steady-state gains (engineering units)")
    doc.image(files[1], "scaled gains")
    doc.table(["", *st.parameters], _matrix_rows(st.variables, st.gains, ".3g"))
    if sob is not None:
        doc.heading(f"Sobol total-effect indices (N = {sob.samples}, {sob.runs} runs)")
        doc.image(files[2], "Sobol")
        doc.table(["", *sob.parameters], _matrix_rows(sob.variables, sob.total, ".2f"))
    if agr is not None:
        doc.paragraph(f"Sobol and RGA choose the same parameter for {agr.agree} of {agr.compared} variables:")
        doc.bullets([f"{v}: RGA `{a}`, Sobol `{b}`" + ("" if same else " (differs)" if a and b else
                                                         " (not compared)") for v, a, b, same in agr.rows if a or b])
    md = doc.write_markdown(out / "pairing.md")
    target = out / "pairing.json"
    write_text_atomic(target, json.dumps(result.to_json(), indent=2) + "\n")
    return StageReport(markdown=md, files=(*files, md, target), document=doc)
