"""``trackingbox estimate``: initial parameter values by bounded gray-box estimation."""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  trackingbox estimate case1/spec.toml
  trackingbox estimate case1/spec.toml --report case1/estimate --seed 3 --workers 2
  trackingbox estimate case1/spec.toml --maxiter 10 --popsize 8 --json
  trackingbox estimate case1/spec.toml --write      # estimates become the [[parameters]] start values
  trackingbox estimate hp/spec.toml --workers 2 --maxiter 8 --refine-iterations 6   # ~3-4 min budget

The cost is the NRMSE (RMSE / measured range) per output tag, averaged over the
tags, on the training window; the validation window reports the NRMSE at the
estimate and at the start values. With --report DIR a checkpoint
(DIR/checkpoint.json, best point so far) is kept up to date during the run.

Budget: the global search (differential evolution, scored on a --global-grid
grid) runs --maxiter generations of max(2, ceil(15 / n)) * n individuals; by
default at most 480 simulations. The refinement then takes up to two passes of
--refine-iterations least-squares iterations, each 1 + n simulations (the n of
the Jacobian in parallel over --workers). Progress (with the time left at most)
goes to stderr.
"""


def register(subparsers: Any) -> None:
    """Add the ``estimate`` subcommand."""
    from ..estimation import (DEFAULT_GLOBAL_EVALUATIONS, DEFAULT_GLOBAL_GRID, DEFAULT_MAXITER, DEFAULT_POPULATION,
                              DEFAULT_WARMUP, MAX_REFINE_ITERATIONS)

    p = subparsers.add_parser(
        "estimate",
        help="estimate the spec's [[parameters]] from the measurements (training/validation windows)",
        description="Bounded gray-box estimation: differential evolution, then least-squares refinement.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--report", type=Path, metavar="DIR",
                   help="write fit plots, convergence trace, parameter table and a checkpoint to DIR")
    p.add_argument("--seed", type=int, default=0, help="seed of the global search (default 0)")
    p.add_argument("--workers", type=int, default=1, help="processes evaluating the population (default 1)")
    p.add_argument("--maxiter", type=int, default=None,
                   help=f"generations of differential evolution (default {DEFAULT_MAXITER}, fewer when the "
                        f"population times generations would exceed {DEFAULT_GLOBAL_EVALUATIONS} simulations; "
                        "0: refinement only)")
    p.add_argument("--global-grid", type=float, default=DEFAULT_GLOBAL_GRID, metavar="SECONDS",
                   help="grid step of the global search's cost (inputs averaged over it; the refinement and "
                        f"the reported NRMSE use sample_time; default {DEFAULT_GLOBAL_GRID:g} s)")
    p.add_argument("--popsize", type=int, default=None,
                   help=f"population size per parameter (default max(2, ceil({DEFAULT_POPULATION} / n_parameters)))")
    p.add_argument("--warmup", type=float, default=DEFAULT_WARMUP, metavar="SECONDS",
                   help="unscored warm-up before each window: measured history where there is some, "
                        f"else inputs held at their first values (default {DEFAULT_WARMUP:g} s)")
    p.add_argument("--no-refine", dest="refine", action="store_false",
                   help="skip the least-squares refinement")
    p.add_argument("--refine-iterations", type=int, default=MAX_REFINE_ITERATIONS, metavar="N",
                   help=f"most least-squares iterations (default {MAX_REFINE_ITERATIONS}; "
                        "each costs 1 + n_parameters simulations)")
    p.add_argument("--write", action="store_true",
                   help="write the estimates back as the [[parameters]] start values of SPEC")
    p.set_defaults(func=run)


class _Progress:
    """One status line on stderr (rewritten in place on a terminal), with elapsed time and an estimate
    of the time left in the current stage (at most its budget: a stage may stop earlier)."""

    def __init__(self, quiet: bool = False, every: float = 15.0) -> None:
        self.tty = sys.stderr.isatty()
        self.quiet = quiet
        self.every = every
        self.t0 = time.perf_counter()
        self.stage = ""
        self.stage_t0 = self.t0
        self.stage_i0 = 0
        self.last = -1.0e9
        self.last_call = self.t0

    def __call__(self, stage: str, iteration: int, total: int, best: float) -> None:
        if self.quiet:
            return
        now = time.perf_counter()
        if stage != self.stage:
            self.stage, self.stage_t0, self.stage_i0 = stage, self.last_call, 0
        self.last_call = now
        elapsed = now - self.t0
        rate = (now - self.stage_t0) / max(iteration - self.stage_i0, 1)
        left = f", at most ~{_duration(rate * (total - iteration))} left" if iteration < total else ""
        if stage == "global":
            text = f"global search: generation {iteration}/{total}, best NRMSE {best:.5g}"
        elif stage == "refine":
            if not self.tty and now - self.last < self.every:
                return
            text = f"refinement: simulation {iteration}/{total} (budget), rms NRMSE {best:.5g}"
        else:
            text = f"refinement done: NRMSE {best:.5g}"
            left = ""
        text += f" ({_duration(elapsed)} elapsed{left})"
        self.last = now
        if self.tty:
            sys.stderr.write("\r\033[K" + text)
            if stage == "local":
                sys.stderr.write("\n")
        else:
            sys.stderr.write(text + "\n")
        sys.stderr.flush()


def _duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``1 h 02 min``."""
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"
    return f"{int(seconds // 3600)} h {int(seconds % 3600 // 60):02d} min"


def run(args: argparse.Namespace) -> int:
    """Run the estimation; exit code 0 on success."""
    from ..estimation import estimate, write_starts
    from ..spec import check_against_fmu, load_spec

    spec = load_spec(args.spec)
    check_against_fmu(spec)
    checkpoint = args.report / "checkpoint.json" if args.report else None
    progress = _Progress()
    result = estimate(
        spec,
        seed=args.seed,
        workers=args.workers,
        maxiter=args.maxiter,
        popsize=args.popsize,
        warmup=args.warmup,
        refine=args.refine,
        refine_iterations=args.refine_iterations,
        progress=progress,
        checkpoint=checkpoint,
        global_grid=args.global_grid,
    )
    if args.report:
        write_report(spec, result, args.report, warmup=args.warmup)
    if args.write:
        write_starts(spec.path, result.parameters)
        log.info("wrote the estimates as start values to %s", spec.path)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        _print_table(result)
        if args.write:
            print(f"wrote start values to {spec.path}")
        if args.report:
            print(f"report in {args.report}")
    return 0


def _print_table(result: Any) -> None:
    width = max(len(n) for n in result.parameters)
    print(f"{'parameter':<{width}}  {'start':>12}  {'estimate':>12}  {'min':>12}  {'max':>12}")
    for name, value in result.parameters.items():
        lo, hi = result.bounds[name]
        print(f"{name:<{width}}  {result.initial[name]:>12.6g}  {value:>12.6g}  {lo:>12.6g}  {hi:>12.6g}")
    tags = list(result.validation_nrmse)
    twidth = max(len(t) for t in tags)
    print()
    print(f"{'tag':<{twidth}}  {'train NRMSE':>12}  {'valid NRMSE':>12}  {'valid (start)':>13}")
    for tag in tags:
        print(f"{tag:<{twidth}}  {result.training_nrmse[tag]:>12.4g}  {result.validation_nrmse[tag]:>12.4g}"
              f"  {result.validation_nrmse_initial[tag]:>13.4g}")
    print(f"\n{result.evaluations} simulations in {result.seconds:.1f} s")


def _safe(tag: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in tag)


def write_report(spec: Any, result: Any, out: Path, *, warmup: float | None = None) -> list[Path]:
    """Fit plots per tag, convergence trace, parameter table and result JSON in *out*.

    Every file is written atomically. Returns the paths written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..estimation import fit_series
    from ..io import atomic_path, write_text_atomic

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    series = fit_series(spec, {"initial": result.initial, "estimated": result.parameters}, warmup=warmup)
    for tag in spec.outputs:
        fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
        for ax, (window, frame) in zip(axes, series.items()):
            hours = frame["time"] / 3600.0
            ax.plot(hours, frame[tag], ".", ms=2, color="0.4", label="measured (used in cost)")
            ax.plot(hours, frame[f"{tag}:initial"], "-", lw=1.2, color="tab:orange", label="start values")
            ax.plot(hours, frame[f"{tag}:estimated"], "-", lw=1.2, color="tab:blue", label="estimate")
            nr = (result.training_nrmse if window == "training" else result.validation_nrmse)[tag]
            ax.set_title(f"{tag}: {window} (NRMSE {nr:.3g})")
            ax.set_xlabel("time from first sample (h)")
            ax.grid(alpha=0.3)
        axes[0].set_ylabel(f"{tag} ({spec.outputs[tag]})")
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        target = out / f"fit_{_safe(tag)}.png"
        with atomic_path(target) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
        plt.close(fig)
        written.append(target)

    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.semilogy(range(len(result.history)), result.history, "o-", ms=3)
    ax.set_xlabel("generation (0: start values; last point: after refinement)")
    ax.set_ylabel("best training cost (mean NRMSE)")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    target = out / "convergence.png"
    with atomic_path(target) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    written.append(target)

    lines = [
        f"# Parameter estimation: {Path(spec.path).name}",
        "",
        f"Twin `{Path(spec.twin).name}`, {result.evaluations} simulations in {result.seconds:.1f} s, "
        f"unscored warm-up of {result.warmup:g} s before each window (the measured history where there "
        "is some, else the inputs held at their first values).",
        "",
        "| parameter | start | estimate | min | max | at bound |",
        "|---|---:|---:|---:|---:|---|",
    ]
    for name, value in result.parameters.items():
        lo, hi = result.bounds[name]
        tol = 1e-6 * (hi - lo)
        at = "min" if value - lo <= tol else "max" if hi - value <= tol else ""
        lines.append(f"| `{name}` | {result.initial[name]:.6g} | {value:.6g} | {lo:.6g} | {hi:.6g} | {at} |")
    lines += [
        "",
        "NRMSE = RMSE / (max - min of the measured tag over the window's valid samples).",
        "",
        "| tag | training | validation | validation at start values | change |",
        "|---|---:|---:|---:|---:|",
    ]
    for tag in result.validation_nrmse:
        v, v0 = result.validation_nrmse[tag], result.validation_nrmse_initial[tag]
        change = f"{100.0 * (v - v0) / v0:+.1f} %" if v0 > 0 else ""
        lines.append(f"| `{tag}` | {result.training_nrmse[tag]:.4g} | {v:.4g} | {v0:.4g} | {change} |")
    lines += ["", "![convergence](convergence.png)", ""]
    lines += [f"![{tag}](fit_{_safe(tag)}.png)" for tag in spec.outputs]
    target = out / "parameters.md"
    write_text_atomic(target, "\n".join(lines) + "\n")
    written.append(target)
    target = out / "result.json"
    write_text_atomic(target, json.dumps({**result.to_json(), "history": list(result.history)}, indent=2) + "\n")
    written.append(target)
    return written
