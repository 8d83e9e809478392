"""``trackingbox estimate``: initial parameter values by bounded gray-box estimation."""
from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

from ..errors import EstimationError
from ..estimation import (
    DEFAULT_GLOBAL_EVALUATIONS,
    DEFAULT_GLOBAL_GRID,
    DEFAULT_MAXITER,
    DEFAULT_POPULATION,
    DEFAULT_WARMUP,
    MAX_REFINE_ITERATIONS,
    write_starts,
)
from ..io import check_output, output_dir
from ..report import write_estimate_report
from ..spec import check_against_fmu, load_spec
from ..stages import estimate as stage
from ..stages.contract import settings_from_args
from . import SUMMARIES
from ._args import add_executor_arguments, number
from ._progress import Progress

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  trackingbox estimate case1/spec.toml
  trackingbox estimate case1/spec.toml --report case1/estimate --seed 3 --workers 2
  trackingbox estimate case1/spec.toml --maxiter 10 --popsize 8 --json
  trackingbox estimate case1/spec.toml --write      # estimates become the [[parameters]] start values
  trackingbox estimate case1/spec.toml --report case1/estimate --resume   # continue after an interruption
  trackingbox estimate hp/spec.toml --workers 2 --maxiter 8 --refine-iterations 6   # ~3-4 min budget
  trackingbox estimate hp/spec.toml --scheduler tcp://10.0.0.5:8786   # population on a Dask cluster
  trackingbox estimate wall/spec.toml --level 0.9    # 90 % intervals

Before the search the sensitivities at the start values say what the data can
determine (a warning names parameters they cannot tell apart; `trackingbox
identify SPEC` gives the whole analysis); after it each parameter gets a
confidence interval (default 95 %, --level) with its method named, or "not
determined (with ...)" and intervals of the combinations that are.

The cost is the NRMSE (RMSE / measured range) per output tag, averaged over the
tags, on the training window; the validation window reports the NRMSE at the
estimate and at the start values. With --report DIR a checkpoint
(DIR/checkpoint.json, best point so far) is kept up to date during the run and
DIR/checkpoint.journal records every evaluation: --resume continues a killed
run from it and gives the uninterrupted run's result, bit for bit.

Budget: the global search (differential evolution, scored on a --global-grid
grid) runs --maxiter generations of max(2, ceil(15 / n)) * n individuals; by
default at most 480 simulations. The refinement then takes up to two passes of
--refine-iterations least-squares iterations, each 1 + n simulations (the n of
the Jacobian in parallel over --workers, or over a Dask cluster's workers with
--scheduler: the same estimate either way). Progress (with the time left at most)
goes to stderr.
"""


def register(subparsers: Any) -> None:
    """Add the ``estimate`` subcommand."""
    p = subparsers.add_parser(
        "estimate",
        help=SUMMARIES["estimate"],
        description="Bounded gray-box estimation: differential evolution, then least-squares refinement.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--report", type=Path, metavar="DIR",
                   help="write fit plots, convergence trace, parameter table and a checkpoint to DIR")
    p.add_argument("--seed", type=number(ge=0, integer=True), default=0, help="seed of the global search (default 0)")
    add_executor_arguments(p, what="the population and the fd Jacobian columns evaluated",
                           default="1, in this process")
    p.add_argument("--maxiter", type=number(ge=0, integer=True), default=None,
                   help=f"generations of differential evolution (default {DEFAULT_MAXITER}, fewer when the "
                        f"population times generations would exceed {DEFAULT_GLOBAL_EVALUATIONS} simulations; "
                        "0: refinement only)")
    p.add_argument("--global-grid", type=number(gt=0), default=DEFAULT_GLOBAL_GRID, metavar="SECONDS",
                   help="grid step of the global search's cost (inputs averaged over it; the refinement and "
                        f"the reported NRMSE use sample_time; default {DEFAULT_GLOBAL_GRID:g} s)")
    p.add_argument("--popsize", type=number(ge=1, integer=True), default=None,
                   help=f"population size per parameter (default max(2, ceil({DEFAULT_POPULATION} / n_parameters)))")
    p.add_argument("--warmup", type=number(ge=0), default=DEFAULT_WARMUP, metavar="SECONDS",
                   help="unscored warm-up before each window: measured history where there is some, "
                        f"else inputs held at their first values (default {DEFAULT_WARMUP:g} s)")
    p.add_argument("--no-refine", dest="refine", action="store_false",
                   help="skip the least-squares refinement")
    p.add_argument("--refine-iterations", type=number(ge=0, integer=True), default=MAX_REFINE_ITERATIONS, metavar="N",
                   help=f"most least-squares iterations (default {MAX_REFINE_ITERATIONS}; "
                        "each costs 1 + n_parameters simulations, or one sensitivity run)")
    p.add_argument("--jacobian", choices=("auto", "exact", "fd", "prefer-exact"), default="auto",
                   help="refinement Jacobian: exact (sensitivity equations from the twin's directional "
                        "derivatives), fd (finite differences), auto (fd where the twin runs on the native "
                        "stepper, measured cheaper; else exact where the twin provides them) or prefer-exact "
                        "(exact where the twin provides them, else fd)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run from DIR/checkpoint.journal (needs --report DIR)")
    p.add_argument("--write", action="store_true",
                   help="write the estimates back as the [[parameters]] start values of SPEC, with their "
                        "intervals (interval = [a, b], where determined: the tracked parameter's band starts "
                        "from it)")
    p.add_argument("--level", type=number(gt=0, le=0.9999), default=0.95,
                   help="confidence level of the intervals at the estimate (default 0.95)")
    p.add_argument("--no-intervals", dest="intervals", action="store_false",
                   help="no confidence intervals (saves their twin runs)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the estimation; exit code 0 on success."""
    if args.resume and not args.report:
        raise EstimationError("--resume needs --report DIR: the checkpoint and its journal live there")
    spec = load_spec(args.spec)
    if args.report:
        check_output(args.report, "--report", kind="dir", inputs=[spec.path, spec.twin, spec.measurements])
    check_against_fmu(spec)
    checkpoint = args.report / "checkpoint.json" if args.report else None
    progress = Progress(every=15.0)
    with output_dir(args.report or "."):
        return _run(args, spec, checkpoint, progress)


def _run(args: argparse.Namespace, spec: Any, checkpoint: Any, progress: Any) -> int:
    result = stage.run(spec, settings_from_args(stage.EstimateSettings, args, checkpoint=checkpoint,
                                                level=args.level if args.intervals else None),
                       progress=progress)
    if args.report:
        write_estimate_report(spec, result, args.report, warmup=args.warmup)
    if args.write:
        write_starts(spec.path, result.parameters, _intervals(result))
        log.info("wrote the estimates as start values to %s", spec.path)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        _print_table(result, spec.path)
        if args.write:
            print(f"wrote start values to {spec.path}")
        if args.report:
            print(f"report in {args.report}")
    return 0


def _intervals(result: Any) -> dict[str, tuple[float, float]]:
    """The determined parameters' intervals (the spec's ``interval``, the band's start)."""
    unc = result.uncertainty
    if unc is None:
        return {}
    return {iv.name: (iv.lower, iv.upper) for iv in unc.parameters
            if iv.determined and iv.lower is not None and iv.lower <= iv.estimate <= iv.upper}


def _print_table(result: Any, spec_path: Any = "SPEC") -> None:
    unc = result.uncertainty
    width = max(len("parameter"), *(len(n) for n in result.parameters))
    level = f"{100 * unc.level:g} % interval" if unc is not None else ""
    print(f"{'parameter':<{width}}  {'start':>12}  {'estimate':>12}  {'min':>12}  {'max':>12}  {level}")
    for name, value in result.parameters.items():
        lo, hi = result.bounds[name]
        iv = unc.interval(name) if unc is not None else None
        what = "" if iv is None else (f"[{iv.lower:.6g}, {iv.upper:.6g}] {iv.method}" if iv.determined else iv.note)
        print(f"{name:<{width}}  {result.initial[name]:>12.6g}  {value:>12.6g}  {lo:>12.6g}  {hi:>12.6g}  {what}")
    if unc is not None and unc.combinations:
        print()
        for iv in unc.combinations:
            print(f"determined: {iv.name} = {iv.text()}")
    if unc is not None:
        for f in unc.findings:
            print(f"note: {f.message}")
        if unc.lack_of_fit is not None and unc.lack_of_fit.message():
            print(f"note: {unc.lack_of_fit.message(spec_path)}")
        for iv in unc.parameters + unc.combinations:
            if iv.determined and iv.note:
                print(f"note: {iv.name}: {iv.note}")
    tags = list(result.validation_nrmse)
    twidth = max(len(t) for t in tags)
    print()
    print(f"{'tag':<{twidth}}  {'train NRMSE':>12}  {'valid NRMSE':>12}  {'valid (start)':>13}")
    for tag in tags:
        print(f"{tag:<{twidth}}  {result.training_nrmse[tag]:>12.4g}  {result.validation_nrmse[tag]:>12.4g}"
              f"  {result.validation_nrmse_initial[tag]:>13.4g}")
    print(f"\n{result.evaluations} simulations in {result.seconds:.1f} s")
    if result.warmup_note():
        print(result.warmup_note())
    if result.refinement:
        why = f" ({result.refinement['reason']})" if result.refinement.get("reason") else ""
        print(f"refinement Jacobian: {result.refinement['jacobian']}{why}")
