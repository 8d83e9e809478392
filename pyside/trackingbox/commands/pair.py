"""``trackingbox pair``: choose tracking parameters for tracking variables (RGA and/or Sobol)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ..io import check_output
from ..report import Document, write_pair_report
from ..spec import check_against_fmu, load_spec, write_pairs
from ..stages import pair as stage
from ..stages.contract import settings_from_args
from . import SUMMARIES
from ._args import add_executor_arguments, number, parse_assignments
from ._progress import Progress

EPILOG = """\
examples:
  trackingbox pair case1/spec.toml
  trackingbox pair case2/spec.toml --freeze holdControllers=1 --report case2/pair
  trackingbox pair ev/spec.toml --freeze holdLevelControllers=1   # flow loop left active
  trackingbox pair case2/spec.toml --method both --samples 64 --workers 2 --json --no-write
  trackingbox pair case2/spec.toml --scheduler tcp://10.0.0.5:8786     # run on a Dask cluster
  trackingbox pair case2/spec.toml --scheduler local --workers 2       # a local Dask cluster of 2 workers

Procedure (in full: the docstring of trackingbox.analysis.pair_stage): settle
the twin at an operating point, --freeze its controllers, step each parameter by
+/- --step of its range; scaled steady-state gains -> RGA -> assignment, after
data checks on an untracked run (with a freeze, judged with step tests repeated
with nothing frozen, which also pair the controller outputs the freeze hides;
see --check-gains). The chosen pairs replace the spec's [[pairs]] unless
--no-write. Exit code 1 when no pair could be chosen.
"""


def register(subparsers: Any) -> None:
    """Add the ``pair`` subcommand."""
    p = subparsers.add_parser(
        "pair",
        help=SUMMARIES["pair"],
        description="Steady-state step tests on the twin with its controllers frozen, relative gain "
                    "array and assignment; optional Sobol sensitivity as a cross-check.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml")
    p.add_argument("--method", choices=("rga", "sobol", "both"), default="rga",
                   help="rga: pairs from the relative gain array (default); sobol: pairs from Sobol total "
                        "indices; both: RGA pairs plus Sobol indices and their agreement")
    p.add_argument("--step", type=number(gt=0, le=1), default=0.05,
                   help="parameter step as a fraction of its bound range (default 0.05)")
    p.add_argument("--one-sided", action="store_true", help="only step up (no -step linearity check)")
    frozen = p.add_mutually_exclusive_group()
    frozen.add_argument("--freeze", action="append", default=None, metavar="NAME=VALUE",
                   help="input or tunable parameter that freezes the twin's controllers, set after the first "
                        "settle (repeatable), e.g. --freeze holdControllers=1; replaces the spec's "
                        "[pairing] freeze (default: that table)")
    frozen.add_argument("--no-freeze", action="store_true",
                   help="freeze nothing, whatever the spec's [pairing] freeze says")
    p.add_argument("--at", type=number(ge=0, le=1e9), metavar="TIME",
                   help="operating point at TIME (s) instead of the first hour of the training window")
    p.add_argument("--interval", type=number(gt=0, le=1e9), metavar="SECONDS",
                   help="communication step of the step tests (default: the spec's sample_time)")
    p.add_argument("--window", type=number(gt=0, le=1e9), metavar="SECONDS",
                   help="settle window (default: 60 intervals)")
    p.add_argument("--tolerance", type=number(gt=0, le=0.5), default=1e-4,
                   help="settled: no output moves more than this fraction of its range in a window (default 1e-4)")
    p.add_argument("--baseline-tolerance", type=number(gt=0), default=1e-3,
                   help="the same for the settle phases before the steps (default 1e-3)")
    p.add_argument("--max-time", type=number(gt=0, le=1e9), default=86400.0, metavar="SECONDS",
                   help="longest a phase may take to settle (default 86400 s)")
    p.add_argument("--rank-tol", type=number(gt=0, le=1), default=None, metavar="RTOL",
                   help="leave out parameters that add less than RTOL x the largest singular value (default 1e-2)")
    p.add_argument("--second-point", default="auto", metavar="auto|none|TIME",
                   help="repeat the step tests at a second operating point: auto (default: the hour of the "
                        "training window whose running inputs differ most from the first point), TIME, or none")
    p.add_argument("--no-identify", dest="identify", action="store_false",
                   help="do not leave out candidates whose effect on the tags the data cannot tell apart from "
                        "another's (the twin's output sensitivities over the training window; on by default, "
                        "with the data checks)")
    p.add_argument("--no-data-checks", dest="data_checks", action="store_false",
                   help="pair from the gains alone (no untracked run over the training window)")
    p.add_argument("--noise-ratio", type=number(ge=0), default=5.0, metavar="K",
                   help="leave out tags whose untracked RMS error is below K x their noise (default 5)")
    p.add_argument("--min-reach", type=number(ge=0), default=0.5, metavar="F",
                   help="allow a pair only if the parameter's remaining range moves the tag by at least "
                        "F x its mean untracked offset (default 0.5)")
    p.add_argument("--max-ratio", type=number(gt=0), default=0.25, metavar="R",
                   help="reject pairs predicted to leave more than R of the untracked RMS error (default 0.25)")
    p.add_argument("--max-leak", type=number(ge=0), default=None, metavar="L",
                   help="separation: reject a pair whose parameter a candidate left unpaired moves by more than L "
                        "of its bound range per bound range of that candidate, at the loops' steady state "
                        "(default: the spec's [pairing] max_leak, else no such check)")
    p.add_argument("--max-jitter", type=number(gt=0), default=None, metavar="J",
                   help="loop noise: make no pair's loop faster than the one whose tag noise (as the data show it) "
                        "moves its parameter by a standard deviation of J of its bound range (default: the spec's "
                        "[pairing] max_jitter, else no such limit)")
    p.add_argument("--check-gains", choices=("recording", "structure"), default="recording",
                   help="gains of the reach and prediction checks: recording (default; with a freeze, step tests "
                        "repeated with nothing frozen, as the data were recorded) or structure (the frozen ones)")
    p.add_argument("--closed-loop", type=number(ge=0, le=1e9), default=None, metavar="SECONDS",
                   help="predict each loop at least this slow and tune new pairs for it (default: the spec's "
                        "[pairing] closed_loop, else the step-response time constants; 0: those)")
    p.add_argument("--closed-loop-min", type=number(ge=0, le=1e9), default=None, metavar="SECONDS",
                   help="loop speed per pair: a pair whose prediction fails with the closed loop is predicted "
                        "again with its own loop faster (steps of sqrt 2) down to this before it is refused, and "
                        "is tuned for the slowest loop that passes (default: the spec's [pairing] "
                        "closed_loop_min, else every loop at the closed loop; 0: that)")
    p.add_argument("--samples", type=number(ge=1, le=1_000_000, integer=True), default=32,
                   help="Sobol base sample size N, a power of two; N*(D+2) runs (default 32)")
    p.add_argument("--seed", type=number(ge=0, integer=True), default=0, help="Sobol sampling seed (default 0)")
    add_executor_arguments(p, what="step tests and Sobol runs", default="all cores")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--report", type=Path, metavar="DIR", help="write RGA/gain heatmaps and a Markdown summary")
    p.add_argument("--no-write", dest="write", action="store_false", help="do not write [[pairs]] to SPEC")
    p.set_defaults(func=run)


def settings(args: argparse.Namespace) -> Any:
    """The :class:`~trackingbox.analysis.pair_stage.PairSettings` the arguments ask for."""
    freeze = (() if args.no_freeze else None if args.freeze is None
              else tuple(parse_assignments(args.freeze, "--freeze").items()))
    return settings_from_args(stage.PairSettings, args, two_sided=not args.one_sided, freeze=freeze)


def run(args: argparse.Namespace) -> int:
    """Run ``trackingbox pair``; exit code 0 on success, 1 when no pair was found."""
    spec = load_spec(args.spec)
    if args.report:
        check_output(args.report, "--report", kind="dir", inputs=[spec.path, spec.twin, spec.measurements])
    check_against_fmu(spec)
    progress = Progress()
    result = stage.run(spec, settings(args), progress=progress)
    pairing = result.pairing
    if args.report:
        rep = write_pair_report(spec, result, args.report)
        progress.note(f"report: {', '.join(str(p) for p in rep.files)}")
    if args.write:
        if pairing.pairs:
            write_pairs(spec.path, stage.spec_pairs(spec, result))
            progress.note(f"wrote {len(pairing.pairs)} pairs to {spec.path}")
        else:
            progress.note(f"no pairs found; {spec.path} left unchanged")
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        _print_summary(result)
    return 0 if pairing.pairs else 1


def _print_summary(result: Any) -> None:
    pairing, doc = result.pairing, Document("")
    doc.table(["variable", "parameter", "lambda", "gain", "tau (s)"],
              [[p.variable, p.parameter, f"{p.lambda_:.3f}", f"{p.gain:.4g}", f"{p.time_constant:.4g}"]
               for p in pairing.pairs], align="llrrr")
    print(doc.markdown().rstrip() if pairing.pairs else "no pairs found")
    print(f"\ncondition number (scaled gains): {pairing.condition_number:.4g}; {result.runs} simulations")
    print(f"gains: {result.check_rule}")
    for name, reason in pairing.left_out:
        kind = "parameter" if name in pairing.parameters else "tag"
        print(f"left out {kind} {name}: {reason}")
    for w in result.warnings:
        print(f"warning: {w}")
    if result.agreement is not None:
        a = result.agreement
        print(f"Sobol ({a.index} index) agrees with the RGA for {a.agree} of {a.compared} variables")
