"""``trackingbox track``: run the tracking simulator over the spec's measurements."""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  trackingbox track case1/spec.toml
  trackingbox track case1/spec.toml --report case1/track --window validation
  trackingbox track case1/spec.toml --out case1/run --json
  trackingbox track case1/spec.toml --out case1/run --resume     # continue after an interruption

One parameter controller per [[pairs]] entry (setpoint: the measured tag; process
value: the twin's variable; output: the parameter, scaled 0-100 % onto its
bounds; gains from kp/ti or SIMC-tuned from gain and time_constant), state
compensation per [[states]] entry, start-up hold until [tracking] hold_until.
The run streams OUT/tracking.csv (measured, tracked and untracked values,
parameters, corrections, controller modes) and checkpoints OUT/checkpoint.json.
NRMSE = RMSE / measured range over the chosen window after the start-up hold.
"""


def register(subparsers: Any) -> None:
    """Add the ``track`` subcommand."""
    p = subparsers.add_parser(
        "track",
        help="run the tracking simulator (parameter controllers) over the measurements",
        description="Step the twin beside the plant data and adjust the paired parameters so the "
                    "twin follows the measurements.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml (with [[pairs]])")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--report", type=Path, metavar="DIR", help="write plots and a Markdown summary to DIR")
    p.add_argument("--out", type=Path, metavar="DIR",
                   help="where tracking.csv and checkpoint.json go (default: DIR of --report, "
                        "else 'track' beside the spec)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.json")
    p.add_argument("--window", choices=("training", "validation", "all"), default="all",
                   help="window the NRMSE figures are taken over, after the start-up hold; the run "
                        "goes from the first sample to the window's end (default: all)")
    p.add_argument("--checkpoint-every", type=int, default=200, metavar="N",
                   help="rows between checkpoints (default 200)")
    p.set_defaults(func=run)


class _Progress:
    """A status line on stderr: rows done, simulated time, speed."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty()
        self.t0 = time.perf_counter()
        self.last = 0.0

    def __call__(self, done: int, total: int) -> None:
        now = time.perf_counter()
        if done < total and now - self.last < (0.2 if self.tty else 5.0):
            return
        self.last = now
        text = f"tracking: row {done}/{total} ({100.0 * done / max(total, 1):.0f} %), {now - self.t0:.1f} s"
        if self.tty:
            sys.stderr.write("\r\033[K" + text + ("\n" if done >= total else ""))
        else:
            sys.stderr.write(text + "\n")
        sys.stderr.flush()


def run(args: argparse.Namespace) -> int:
    """Run the tracking simulator; exit code 0 on success."""
    from ..errors import SpecError
    from ..spec import load_spec
    from ..tracking.runtime import track

    if args.checkpoint_every < 1:
        raise SpecError(f"--checkpoint-every must be >= 1, got {args.checkpoint_every}")
    spec = load_spec(args.spec)
    out = args.out or args.report or Path(spec.path).parent / "track"
    result = track(spec, out_dir=out, resume=args.resume, progress=_Progress(), window=args.window,
                   checkpoint_every=args.checkpoint_every)
    if args.report:
        write_report(spec, result, args.report)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        _print_summary(result, {p.variable: p.parameter for p in spec.pairs})
        if args.report:
            print(f"report in {args.report}")
    return 0


def _fmt(x: float) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.4g}"


def _summary_lines(result: Any, paired: dict[str, str] | None = None) -> list[str]:
    """Markdown tables; *paired* maps each tracking variable to its parameter (listed first)."""
    paired = paired or {}
    lines = ["| tag | tracked by | NRMSE untracked | NRMSE tracked | ratio | samples |",
             "|---|---|---:|---:|---:|---:|"]
    order = [t for t in result.variables if t in paired] + [t for t in result.variables if t not in paired]
    for tag in order:
        v = result.variables[tag]
        ratio = v.nrmse_tracked / v.nrmse_untracked if v.nrmse_untracked and math.isfinite(v.nrmse_untracked) \
            else math.nan
        by = f"`{paired[tag]}`" if tag in paired else ""
        lines.append(f"| {tag} | {by} | {_fmt(v.nrmse_untracked)} | {_fmt(v.nrmse_tracked)} | {_fmt(ratio)} "
                     f"| {v.samples} |")
    lines += ["", "| parameter | final | min | max | lower bound | upper bound |", "|---|---:|---:|---:|---:|---:|"]
    for name, p in result.parameters.items():
        lines.append(f"| {name} | {_fmt(p.final)} | {_fmt(p.min)} | {_fmt(p.max)} | {_fmt(p.lower)} | {_fmt(p.upper)} |")
    if result.corrections:
        lines += ["", "| correction (kg/s) | final | min | max |", "|---|---:|---:|---:|"]
        for name, c in result.corrections.items():
            lines.append(f"| {name} | {_fmt(c.final)} | {_fmt(c.min)} | {_fmt(c.max)} |")
    return lines


def _print_summary(result: Any, paired: dict[str, str] | None = None) -> None:
    for line in _summary_lines(result, paired):
        print(line)
    state = "complete" if result.complete else "stopped early (resume to continue)"
    print(f"\n{result.steps} rows, {result.simulated_seconds:g} s simulated in {result.seconds:.1f} s; {state}")
    print(f"trajectory: {result.csv}")


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def write_report(spec: Any, result: Any, out: Path) -> list[Path]:
    """Plots (measured/untracked/tracked per tag, parameters with bounds, corrections) and ``summary.md``.

    (``result.json`` with the full figures is written by the run itself, into its output directory.)

    Every file is written atomically; returns the paths written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from ..io import atomic_path, write_text_atomic

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    df = pd.read_csv(result.csv)
    hours = df["time"].to_numpy() / 3600.0
    hold = float(spec.tracking.hold_until) / 3600.0
    written: list[Path] = []
    figures: list[tuple[str, str]] = []

    def save(fig: Any, name: str, title: str) -> None:
        target = out / name
        with atomic_path(target) as tmp:
            fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        written.append(target)
        figures.append((title, name))

    tags = [c.split(":", 1)[1] for c in df.columns if c.startswith("tracked:")]
    for tag in tags:
        fig, ax = plt.subplots(figsize=(9, 3.6))
        ax.plot(hours, df[f"measured:{tag}"], ".", ms=2, color="0.55", label="measured")
        if df[f"untracked:{tag}"].notna().any():
            ax.plot(hours, df[f"untracked:{tag}"], color="tab:orange", lw=1.2, label="untracked twin")
        ax.plot(hours, df[f"tracked:{tag}"], color="tab:blue", lw=1.2, label="tracked twin")
        if hold > 0:
            ax.axvspan(0, hold, color="0.9", zorder=0, label="start-up hold")
        ax.set_xlabel("time (h)")
        ax.set_ylabel(tag)
        ax.legend(loc="best", fontsize=8)
        ax.set_title(f"{tag}: measured, untracked and tracked")
        save(fig, f"tag_{_safe(tag)}.png", f"{tag}")

    for name, p in result.parameters.items():
        fig, ax = plt.subplots(figsize=(9, 3.2))
        ax.plot(hours, df[f"parameter:{name}"], color="tab:green", lw=1.2, label=name)
        ax.axhline(p.lower, color="k", ls="--", lw=0.8, label="bounds")
        ax.axhline(p.upper, color="k", ls="--", lw=0.8)
        hold_rows = df[[c for c in df.columns if c.startswith("mode:")]].eq("hold").any(axis=1).to_numpy()
        if hold_rows.any():
            ax.fill_between(hours, p.lower, p.upper, where=hold_rows, color="0.92", step="mid",
                            label="controller on hold")
        ax.set_xlabel("time (h)")
        ax.set_ylabel(name)
        ax.legend(loc="best", fontsize=8)
        ax.set_title(f"tracking parameter {name}")
        save(fig, f"parameter_{_safe(name)}.png", f"parameter {name}")

    corr_cols = [c for c in df.columns if c.startswith("correction:")]
    if corr_cols:
        fig, ax = plt.subplots(figsize=(9, 3.2))
        for c in corr_cols:
            ax.plot(hours, df[c], lw=1.0, label=c.split(":", 1)[1])
        ax.set_xlabel("time (h)")
        ax.set_ylabel("correction flow (kg/s)")
        ax.legend(loc="best", fontsize=8)
        ax.set_title("state compensation")
        save(fig, "corrections.png", "state compensation")

    md = [f"# Tracking run: {Path(spec.path).name}", "",
          f"- twin: `{Path(spec.twin).name}`, sample time {spec.sample_time:g} s, "
          f"start-up hold until {spec.tracking.hold_until:g} s",
          f"- metrics over [{result.window[0]:g}, {result.window[1]:g}) s (after the hold; stoppages and "
          "missing samples excluded); NRMSE = RMSE / measured range",
          f"- {result.steps} rows, {result.simulated_seconds:g} s simulated in {result.seconds:.1f} s wall",
          f"- trajectory: `{result.csv}`", "",
          *_summary_lines(result, {p.variable: p.parameter for p in spec.pairs}), ""]
    if result.events:
        md += ["## Events", ""]
        md += [f"- t = {e.time:g} s, {e.kind}: {e.message}" for e in result.events[:50]]
        if len(result.events) > 50:
            md.append(f"- ... {len(result.events) - 50} more")
        md.append("")
    md += ["## Plots", ""]
    md += [f"![{title}]({name})" for title, name in figures]
    target = out / "summary.md"
    write_text_atomic(target, "\n".join(md) + "\n")
    written.append(target)
    return written
