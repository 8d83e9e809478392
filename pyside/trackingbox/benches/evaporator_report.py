"""The evaporator bench's own checks and plots, against the plant's truth.

:func:`assess` measures the issue's "done" criteria on a tracking run of an
evaporator case: which pairs were chosen (the heat-transfer parameter with the
condensate flow or the effect's temperature/pressure; the valve capacities with
what they move), tracked vs untracked NRMSE per paired tag, the tracked fouling
against the plant's fouling *trajectory* from ``truth.json`` (after settling,
and inside every stoppage), and the twin's levels against their vessels.
:func:`write_evaporator_report` writes the plots: the tracked fouling over the
days against the truth, and levels and temperatures through a stoppage
(measured, untracked twin, tracked twin), stoppages shaded.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..errors import FMUError
from ..report import Document, StageReport, plots
from .evaporator import RF_BOUNDS, stoppage_intervals, truth_on

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Tags the heat-transfer parameter may pair with: condensate flow, body temperature, vapour
#: pressure (the issue), and the product dry solids (the notes' section 4 table: "otherwise p_v
#: or product DS"), read by the DS meter QI-6150 or through its boiling-point rise in the flash
#: tank's temperature TI-6151 (the flash saturates at its pressure plus the product's BPR).
HEAT_TRANSFER_TAGS = ("FI-6125", "PI-6121", "TI-6111", "PI-6111", "QI-6150", "TI-6151")
#: Valve capacity -> tags it moves (closed loop: the valve position; frozen: the flow).
VALVE_TAGS = {"inletValve.KvMax": ("ZI-6110", "FI-6110"), "outletValve.KvMax": ("ZI-6150", "FI-6150")}
#: Level tag -> (twin parameter of its vessel's height, the height declared in the library, m);
#: levels must stay in [0, height]. The FMU's value is used when it exports the parameter.
VESSEL_HEIGHT = {"LI-6111": ("effect.H", 3.0), "LI-6151": ("flash.H", 3.0), "LI-6125": ("condTank.H", 2.0)}


@dataclass(frozen=True)
class FoulingCheck:
    """Tracked fouling against the plant's fouling trajectory.

    Errors are ``|tracked − truth| / (upper − lower)`` of the tracked parameter's
    bounds, expressed as fouling resistance (m2.K/W).
    """

    parameter: str
    settle: float
    """s: errors count from here on."""
    max_error: float
    """Largest error after settling (fraction of the bound range)."""
    max_error_stoppages: float
    """Largest error inside the stoppages (and their settle time) after settling."""
    final_error: float
    within_bounds: bool
    passed: bool


@dataclass(frozen=True)
class LevelCheck:
    """One twin level over the run against its vessel."""

    tag: str
    min: float
    max: float
    height: float
    inside: bool


@dataclass(frozen=True)
class EvaporatorAssessment:
    """The issue's done criteria measured on one run (see :func:`assess`)."""

    pairs: tuple[tuple[str, str], ...]
    heat_transfer_pair: tuple[str, str] | None
    valve_pairs: dict[str, str | None]
    left_out: tuple[tuple[str, str], ...]
    nrmse: dict[str, tuple[float, float, float]]
    """Paired tag -> (untracked, tracked, tracked/untracked) on the metric window."""
    nrmse_ok: bool
    fouling: FoulingCheck | None
    levels: tuple[LevelCheck, ...]
    levels_ok: bool

    def to_json(self) -> dict[str, Any]:
        return {
            "pairs": [list(p) for p in self.pairs],
            "heat_transfer_pair": list(self.heat_transfer_pair) if self.heat_transfer_pair else None,
            "valve_pairs": dict(self.valve_pairs),
            "left_out": [list(x) for x in self.left_out],
            "nrmse": {t: {"untracked": u, "tracked": k, "ratio": r} for t, (u, k, r) in self.nrmse.items()},
            "nrmse_ok": self.nrmse_ok,
            "fouling": asdict(self.fouling) if self.fouling else None,
            "levels": [asdict(x) for x in self.levels],
            "levels_ok": self.levels_ok,
        }


def fouling_equivalent(name: str, values: FloatArray, start: float) -> FloatArray:
    """The tracked parameter as a fouling resistance (m2.K/W).

    ``effect.Rf`` is one; a tracked clean coefficient ``effect.U0`` (with the twin's
    ``Rf`` at 0) is the fouling ``1/U0 − 1/U0_start`` relative to the start value.
    """
    if name == "effect.U0":
        return 1.0 / values - 1.0 / start
    return values


def assess(spec: Any, tracking_csv: str | Path, truth: Mapping[str, Any], *,
           nrmse: Mapping[str, tuple[float, float]], left_out: Sequence[tuple[str, str]] = (),
           heights: Mapping[str, float] | None = None, settle: float = 12 * 3600.0) -> EvaporatorAssessment:
    """Measure the done criteria on a tracking run.

    Parameters
    ----------
    spec : trackingbox.spec.Spec
        The spec the run used (with ``[[pairs]]``).
    tracking_csv : path
        The run's ``tracking.csv``.
    truth : mapping
        The case's ``truth.json`` document.
    nrmse : mapping
        Paired tag -> (untracked, tracked) NRMSE on the metric window (the run's result).
    left_out : sequence of (name, reason)
        From the pairing.
    heights : mapping, optional
        Level tag -> vessel height (m).
    settle : float
        s after which the tracked fouling counts.
    """
    df = pd.read_csv(tracking_csv)
    t = df["time"].to_numpy(float)
    pairs = tuple((p.variable, p.parameter) for p in spec.pairs)
    heat = next(((v, p) for v, p in pairs if p in ("effect.Rf", "effect.U0") and v in HEAT_TRANSFER_TAGS), None)
    valves = {name: next((v for v, p in pairs if p == name and v in tags), None) for name, tags in VALVE_TAGS.items()}
    ratios = {tag: (float(u), float(k), float(k / u) if u > 0 else math.inf) for tag, (u, k) in nrmse.items()}
    fouling = None
    tracked_name = next((p for _, p in pairs if p in ("effect.Rf", "effect.U0")), None)
    truth_rf = truth_on(truth, "effect.Rf", t)
    if tracked_name is not None and truth_rf is not None:
        pspec = next(p for p in spec.parameters if p.name == tracked_name)
        raw = df[f"parameter:{tracked_name}"].to_numpy(float)
        eq = fouling_equivalent(tracked_name, raw, pspec.start)
        span = RF_BOUNDS[1] - RF_BOUNDS[0] if tracked_name == "effect.Rf" else float(
            abs(1.0 / pspec.min - 1.0 / pspec.max))
        fouling = fouling_check(spec, t, raw, eq, truth_rf, truth, name=tracked_name, span=span, settle=settle)
    levels = level_checks(spec, df, heights)
    return EvaporatorAssessment(
        pairs=pairs, heat_transfer_pair=heat, valve_pairs=valves, left_out=tuple(left_out), nrmse=ratios,
        nrmse_ok=bool(ratios) and all(r <= 0.3 for _, _, r in ratios.values()), fouling=fouling,
        levels=tuple(levels), levels_ok=all(x.inside for x in levels))


def fouling_check(spec: Any, t: FloatArray, raw: FloatArray, equivalent: FloatArray, truth_rf: FloatArray,
                  truth: Mapping[str, Any], *, name: str, span: float, settle: float) -> FoulingCheck:
    """Tracked fouling *equivalent* (m2.K/W) against the plant's *truth_rf* on the times *t* (s).

    The error is ``|equivalent - truth_rf| / span``; its largest value from *settle* on, and inside
    the stoppages of *truth* (with the spec's stoppage settle time) from *settle* on; *raw* (the
    tracked parameter itself) against the spec's bounds of *name*. Passed: both at most 10 % and
    inside the bounds.
    """
    pspec = next(p for p in spec.parameters if p.name == name)
    err = np.abs(equivalent - truth_rf) / span
    after = t >= settle
    in_stop = np.zeros(t.shape, dtype=bool)
    rule = spec.data.stoppage
    for a, b in stoppage_intervals(truth):
        in_stop |= (t >= a) & (t <= b + (rule.settle if rule is not None else 0.0))
    e_after = float(np.nanmax(err[after])) if after.any() else math.nan
    e_stop = float(np.nanmax(err[after & in_stop])) if (after & in_stop).any() else math.nan
    inside = bool(np.all((raw >= pspec.min - 1e-12 * abs(pspec.min)) & (raw <= pspec.max + 1e-12 * abs(pspec.max))))
    return FoulingCheck(parameter=name, settle=settle, max_error=e_after, max_error_stoppages=e_stop,
                        final_error=float(err[-1]), within_bounds=inside,
                        passed=bool(e_after <= 0.1 and (math.isnan(e_stop) or e_stop <= 0.1) and inside))


def level_checks(spec: Any, df: pd.DataFrame, heights: Mapping[str, float] | None) -> list[LevelCheck]:
    """Every compensated twin level of a tracking run (``tracked:<tag>``) against its vessel."""
    levels = []
    for st in spec.states:
        col = f"tracked:{st.tag}"
        if col not in df.columns:
            continue
        y = df[col].to_numpy(float)
        h = float((heights or {}).get(st.tag, math.nan))
        lo, hi = float(np.nanmin(y)), float(np.nanmax(y))
        levels.append(LevelCheck(st.tag, lo, hi, h, bool(lo >= 0.0 and (math.isnan(h) or hi <= h))))
    return levels


def vessel_heights(twin_info: Any) -> dict[str, float]:
    """Level tag -> vessel height (m), from the twin FMU's parameters where it exports them."""
    out = {}
    for tag, (name, declared) in VESSEL_HEIGHT.items():
        try:
            var = twin_info.variable(name)
        except FMUError:  # not exported (no equation uses it): the library's declared height
            out[tag] = declared
            continue
        out[tag] = float(var.start) if var.start is not None else declared
    return out


def _longest_stoppage(truth: Mapping[str, Any], t_end: float, after: float) -> tuple[float, float] | None:
    stops = [(a, b) for a, b in stoppage_intervals(truth) if a >= after and b <= t_end]
    return max(stops, key=lambda ab: ab[1] - ab[0]) if stops else None


def write_evaporator_report(spec: Any, tracking_csv: str | Path, truth: Mapping[str, Any], out: str | Path,
                            assessment: EvaporatorAssessment) -> StageReport:
    """Write ``fouling.png``, ``stoppage.png`` and ``evaporator.md`` into *out*."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    df = pd.read_csv(tracking_csv)
    t = df["time"].to_numpy(float)
    hours = t / 3600.0
    stops_h = [(a / 3600.0, b / 3600.0) for a, b in stoppage_intervals(truth)]
    plt = plots.pyplot()
    files: list[Path] = []
    doc = Document("Evaporator: fouling against the plant's truth, and stoppages")

    # 1. tracked fouling over the days vs the plant's trajectory
    fig, ax = plt.subplots(figsize=(10, 3.8))
    plots.shade(ax, stops_h)
    truth_rf = truth_on(truth, "effect.Rf", t)
    if truth_rf is not None:
        ax.plot(hours, truth_rf, ":", color=plots.TRUTH, lw=2.0, label="plant fouling (truth)")
    if assessment.fouling is not None:
        name = assessment.fouling.parameter
        pspec = next(p for p in spec.parameters if p.name == name)
        eq = fouling_equivalent(name, df[f"parameter:{name}"].to_numpy(float), pspec.start)
        ax.plot(hours, eq, color=plots.TRACKED, lw=1.2, label=f"tracked ({name} as Rf)")
        ax.axvline(assessment.fouling.settle / 3600.0, color="0.5", lw=0.8, ls="-.", label="settled")
    ax.axhline(RF_BOUNDS[0], color="k", ls="--", lw=0.8, label="bounds")
    ax.axhline(RF_BOUNDS[1], color="k", ls="--", lw=0.8)
    ax.set_xlabel("time (h)")
    ax.set_ylabel("fouling resistance (m2.K/W)")
    ax.set_title("tracked fouling vs the plant's fouling; stoppages shaded", fontsize=10, loc="left")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    files.append(plots.save(fig, out / "fouling.png"))

    # 2. levels and temperatures through the longest stoppage after the start-up hold
    stop = _longest_stoppage(truth, float(t[-1]), float(spec.tracking.hold_until))
    tags = [s.tag for s in spec.states] + [tag for tag in ("TI-6111", "TI-6151") if f"measured:{tag}" in df.columns]
    if stop is not None:
        a, b = stop
        sel = (t >= a - 2 * 3600.0) & (t <= b + 3 * 3600.0)
        fig, axes = plt.subplots(len(tags), 1, figsize=(10, 2.4 * len(tags)), sharex=True, squeeze=False)
        for i, tag in enumerate(tags):
            axi = axes[i, 0]
            plots.shade(axi, [(a / 3600.0, b / 3600.0)])
            plots.series(axi, hours[sel], df[f"measured:{tag}"].to_numpy(float)[sel],
                         [plots.Line(df[f"untracked:{tag}"].to_numpy(float)[sel], "untracked twin", plots.UNTRACKED),
                          plots.Line(df[f"tracked:{tag}"].to_numpy(float)[sel], "tracked twin", plots.TRACKED)],
                         ylabel=tag, xlabel="time (h)" if i == len(tags) - 1 else None)
        axes[0, 0].set_title(f"through the stoppage at {a / 3600:.1f}-{b / 3600:.1f} h (shaded)", fontsize=10,
                             loc="left")
        files.append(plots.save(fig, out / "stoppage.png"))

    # text
    doc.paragraph(f"{len(stops_h)} stoppages in the run (shaded). Pairs: "
                  + ", ".join(f"`{v}` ↔ `{p}`" for v, p in assessment.pairs) + ".")
    if assessment.fouling is not None:
        f = assessment.fouling
        doc.bullets([f"tracked `{f.parameter}` vs plant fouling, after {f.settle / 3600:g} h: max error "
                     f"{f.max_error:.1%} of the bound range (inside stoppages {f.max_error_stoppages:.1%}), "
                     f"final {f.final_error:.1%}; within bounds: {f.within_bounds}; "
                     f"**{'pass' if f.passed else 'FAIL'}** (≤ 10 %)"])
    doc.table(["tag", "NRMSE untracked", "NRMSE tracked", "ratio"],
              [[t_, f"{u:.4g}", f"{k:.4g}", f"{r:.3g}"] for t_, (u, k, r) in assessment.nrmse.items()])
    return _finish(doc, assessment, files, out / "evaporator.md")


# --------------------------------------------------------------------------- the train (issue 11)

#: Height (m) of the train's vessels by level tag prefix: effects and the flash tank 3 m, the
#: condensate tanks 2 m (``BaseClasses.PartialTrain``).
TRAIN_EFFECT_HEIGHT, TRAIN_CONDENSATE_HEIGHT, TRAIN_FLASH_HEIGHT = 3.0, 2.0, 3.0


@dataclass(frozen=True)
class TrainAssessment:
    """The train's done criteria measured on one run (see :func:`assess_train`)."""

    effects: int
    pairs: tuple[tuple[str, str], ...]
    left_out: tuple[tuple[str, str], ...]
    nrmse: dict[str, tuple[float, float, float]]
    """Paired tag -> (untracked, tracked, tracked/untracked) on the metric window."""
    nrmse_ok: bool
    fouling: dict[str, FoulingCheck | None]
    """``effect[k].Rf`` -> its check, None where no pair drives it."""
    fouling_ok: bool
    """Every effect's fouling paired and passed."""
    levels: tuple[LevelCheck, ...]
    levels_ok: bool
    unpaired_error: dict[str, float]
    """``effect[k].Rf`` no pair drives -> largest error after settling of its start value (held)."""

    def to_json(self) -> dict[str, Any]:
        return {
            "effects": self.effects,
            "unpaired_error": dict(self.unpaired_error),
            "pairs": [list(p) for p in self.pairs],
            "left_out": [list(x) for x in self.left_out],
            "nrmse": {t: {"untracked": u, "tracked": k, "ratio": r} for t, (u, k, r) in self.nrmse.items()},
            "nrmse_ok": self.nrmse_ok,
            "fouling": {n: asdict(f) if f else None for n, f in self.fouling.items()},
            "fouling_ok": self.fouling_ok,
            "levels": [asdict(x) for x in self.levels],
            "levels_ok": self.levels_ok,
        }


def train_heights(spec: Any) -> dict[str, float]:
    """Level tag -> vessel height (m) of the train's compensated levels (from the twin variable's name)."""
    out = {}
    for st in spec.states:
        if st.variable.startswith("LI_body["):
            out[st.tag] = TRAIN_EFFECT_HEIGHT
        elif st.variable.startswith("LI_condensate["):
            out[st.tag] = TRAIN_CONDENSATE_HEIGHT
        elif st.variable == "LI_flash":
            out[st.tag] = TRAIN_FLASH_HEIGHT
    return out


def assess_train(spec: Any, tracking_csv: str | Path, truth: Mapping[str, Any], *,
                 nrmse: Mapping[str, tuple[float, float]], left_out: Sequence[tuple[str, str]] = (),
                 settle: float | None = None) -> TrainAssessment:
    """Measure the train's done criteria on a tracking run: per effect, the tracked fouling
    ``effect[k].Rf`` against the plant's trajectory in *truth* (error as a fraction of the parameter's
    bound range, from *settle* on: default the start of the spec's validation window), tracked over
    untracked NRMSE of every paired tag (<= 0.3), every compensated level inside its vessel.
    """
    df = pd.read_csv(tracking_csv)
    t = df["time"].to_numpy(float)
    n = int(truth.get("effects", 0))
    if settle is None:
        settle = float(spec.windows.get("validation", (12 * 3600.0, 0.0))[0])
    pairs = tuple((p.variable, p.parameter) for p in spec.pairs)
    paired = {p for _, p in pairs}
    ratios = {tag: (float(u), float(k), float(k / u) if u > 0 else math.inf) for tag, (u, k) in nrmse.items()}
    fouling: dict[str, FoulingCheck | None] = {}
    unpaired: dict[str, float] = {}
    for k in range(1, n + 1):
        name = f"effect[{k}].Rf"
        truth_rf = truth_on(truth, name, t)
        col = f"parameter:{name}"
        pspec = next((p for p in spec.parameters if p.name == name), None)
        if name not in paired or truth_rf is None or col not in df.columns or pspec is None:
            fouling[name] = None
            if truth_rf is not None and pspec is not None and (t >= settle).any():
                unpaired[name] = float(np.max(np.abs(pspec.start - truth_rf[t >= settle])) / (pspec.max - pspec.min))
            continue
        raw = df[col].to_numpy(float)
        fouling[name] = fouling_check(spec, t, raw, raw, truth_rf, truth, name=name,
                                      span=float(pspec.max - pspec.min), settle=settle)
    levels = level_checks(spec, df, train_heights(spec))
    return TrainAssessment(
        effects=n, pairs=pairs, left_out=tuple(left_out), nrmse=ratios,
        nrmse_ok=bool(ratios) and all(r <= 0.3 for _, _, r in ratios.values()), fouling=fouling,
        fouling_ok=bool(fouling) and all(f is not None and f.passed for f in fouling.values()),
        levels=tuple(levels), levels_ok=all(x.inside for x in levels), unpaired_error=unpaired)


def write_train_report(spec: Any, tracking_csv: str | Path, truth: Mapping[str, Any], out: str | Path,
                       assessment: TrainAssessment) -> StageReport:
    """Write ``fouling.png`` (one panel per effect: tracked fouling vs the plant's, stoppages shaded)
    and ``evaporator-train.md`` into *out*."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    df = pd.read_csv(tracking_csv)
    t = df["time"].to_numpy(float)
    hours = t / 3600.0
    stops_h = [(a / 3600.0, b / 3600.0) for a, b in stoppage_intervals(truth)]
    plt = plots.pyplot()
    names = list(assessment.fouling)
    doc = Document(f"Evaporator train ({assessment.effects} effects): every effect's fouling against the "
                   "plant's truth")
    files: list[Path] = []
    if names:
        fig, axes = plt.subplots(len(names), 1, figsize=(10, 2.8 * len(names)), sharex=True, squeeze=False)
        for i, name in enumerate(names):
            ax = axes[i, 0]
            plots.shade(ax, stops_h)
            truth_rf = truth_on(truth, name, t)
            if truth_rf is not None:
                ax.plot(hours, truth_rf, ":", color=plots.TRUTH, lw=2.0, label="plant fouling (truth)")
            check = assessment.fouling[name]
            if check is not None:
                ax.plot(hours, df[f"parameter:{name}"].to_numpy(float), color=plots.TRACKED, lw=1.2,
                        label="tracked")
                ax.axvline(check.settle / 3600.0, color="0.5", lw=0.8, ls="-.", label="settled")
            pspec = next((p for p in spec.parameters if p.name == name), None)
            if check is None and pspec is not None:
                ax.axhline(pspec.start, color=plots.TRACKED, lw=1.2, ls="-", label="twin (held at its start)")
            if pspec is not None:
                ax.axhline(pspec.min, color="k", ls="--", lw=0.8, label="bounds")
                ax.axhline(pspec.max, color="k", ls="--", lw=0.8)
            ax.set_ylabel(f"{name} (m2.K/W)", fontsize=8)
            ax.set_title(f"{name}: " + (f"max error after settling {check.max_error:.1%} of the range"
                                        if check is not None else "no pair drives it (held at its start"
                                        + (f": max error after settling {assessment.unpaired_error[name]:.1%})"
                                           if name in assessment.unpaired_error else ")")),
                         fontsize=9, loc="left")
            ax.grid(alpha=0.3)
            ax.legend(loc="best", fontsize=7)
        axes[-1, 0].set_xlabel("time (h)")
        files.append(plots.save(fig, out / "fouling.png"))
    doc.paragraph(f"{len(stops_h)} stoppages in the run (shaded). Pairs: "
                  + ", ".join(f"`{v}` ↔ `{p}`" for v, p in assessment.pairs) + ".")
    doc.table(["effect fouling", "max error after settling", "in stoppages", "final", "within bounds", "≤ 10 %"],
              [[n, f"{f.max_error:.1%}", f"{f.max_error_stoppages:.1%}", f"{f.final_error:.1%}",
                str(f.within_bounds), "pass" if f.passed else "**FAIL**"] if f is not None
               else [n, (f"{assessment.unpaired_error[n]:.1%} (held at its start)" if n in assessment.unpaired_error
                         else "-"), "-", "-", "-", "**not paired**"] for n, f in assessment.fouling.items()])
    doc.table(["tag", "NRMSE untracked", "NRMSE tracked", "ratio", "≤ 0.30"],
              [[t_, f"{u:.4g}", f"{k:.4g}", f"{r:.3g}", "pass" if r <= 0.3 else "**FAIL**"]
               for t_, (u, k, r) in assessment.nrmse.items()])
    return _finish(doc, assessment, files, out / "evaporator-train.md")


def _finish(doc: Document, assessment: Any, files: list[Path], md_path: Path) -> StageReport:
    """The levels and left-out tables, the plots, and the Markdown file: the end of both evaporator reports."""
    doc.table(["level", "min (m)", "max (m)", "vessel height (m)", "inside"],
              [[x.tag, f"{x.min:.3g}", f"{x.max:.3g}", f"{x.height:.3g}", str(x.inside)] for x in assessment.levels])
    if assessment.left_out:
        doc.table(["left out", "reason"], [list(x) for x in assessment.left_out])
    for f in files:
        doc.image(f, f.stem)
    md = doc.write_markdown(md_path)
    return StageReport(markdown=md, files=(*files, md), document=doc)
