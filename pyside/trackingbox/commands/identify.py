"""``trackingbox identify``: what the data can determine of the spec's parameters, before estimating them."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ..identify.analysis import DEFAULT_POINTS, identify
from ..io import check_output, output_dir
from ..report.identify import write_identify_report
from ..simulation.windows import DEFAULT_WARMUP
from ..spec import check_against_fmu, load_spec
from . import SUMMARIES
from ._args import number
from ._progress import Progress

EPILOG = """\
examples:
  trackingbox identify case1/spec.toml
  trackingbox identify wall/spec.toml --points 5 --report wall/identify
  trackingbox identify hp/spec.toml --sensitivities fd --json

At the start values and at --points points spread inside the bounds, the
twin's output sensitivities on the training window (exact from the FMU's
directional derivatives where it provides them, else central differences)
are scaled -- relative changes (log-parameters) where a parameter's bounds are
positive, else its bound range; each tag's samples divided by its sensor noise,
read from the measurements -- and analysed: the numerical rank, the parameter
combinations the data cannot determine, named as products or ratios ("only
R1·C and R2·C are determined") or sums where that is their structure at every
point, else as the direction's numbers, unmeasured twin outputs that would
separate them, and the correlation matrix. A direction counts as determined
when its 95 % interval (sensor noise only: the best case) is at most half as
wide as the bounds allow. Exit code 0 when the analysis ran, whatever it found.
"""


def register(subparsers: Any) -> None:
    """Add the ``identify`` subcommand."""
    p = subparsers.add_parser(
        "identify",
        help=SUMMARIES["identify"],
        description="Identifiability of the spec's parameters from the twin's output sensitivities.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--report", type=Path, metavar="DIR", help="write identify.md, correlation.png and identify.json")
    p.add_argument("--points", type=number(ge=0, integer=True), default=DEFAULT_POINTS,
                   help=f"points inside the bounds checked besides the start values (default {DEFAULT_POINTS})")
    p.add_argument("--sensitivities", choices=("auto", "exact", "fd"), default="auto",
                   help="exact (the FMU's directional derivatives), fd (central differences) or auto "
                        "(exact where the twin provides them)")
    p.add_argument("--warmup", type=number(ge=0), default=DEFAULT_WARMUP, metavar="SECONDS",
                   help=f"unscored warm-up before the window, as estimate's (default {DEFAULT_WARMUP:g} s)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the analysis; exit code 0 when it ran."""
    spec = load_spec(args.spec)
    if args.report:
        check_output(args.report, "--report", kind="dir", inputs=[spec.path, spec.twin, spec.measurements])
    check_against_fmu(spec)
    progress = Progress(every=15.0)
    with output_dir(args.report or "."):
        result = identify(spec, points=args.points, method=args.sensitivities, warmup=args.warmup,
                          progress=lambda stage, done, total: progress("sensitivity runs", done, total))
        if args.report:
            write_identify_report(spec, result, args.report)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        print_result(spec, result)
        if args.report:
            print(f"report in {args.report}")
    return 0


def print_result(spec: Any, result: Any) -> None:
    """The analysis as text."""
    method, reason = result.sensitivities
    n = len(result.names)
    print(f"{Path(spec.path).name}: {n} parameter{'s' if n != 1 else ''}, sensitivities {method}"
          + (f" ({reason})" if reason and reason != "requested" else ""))
    kinds = {"log": "relative change (log)", "range": "bound range"}
    for name, kind in zip(result.names, result.scaling):
        hw = result.half_widths.get(name, math.inf)
        pct = (f"±{100 * math.expm1(hw):.3g} %" if kind == "log" else f"±{hw:.3g} of its range") \
            if math.isfinite(hw) else "unbounded"
        state = "determined" if result.determined[name] else "NOT determined"
        print(f"  {name}: scaled by its {kinds[kind]}; {state} (95 % with sensor noise alone: {pct})")
    print("rows: each tag divided by its noise: "
          + "; ".join(f"{t} {s:.3g} ({src})" for t, (s, src) in result.noise.items()))
    for p in result.points:
        if p.error:
            print(f"{p.label}: the twin failed ({p.error})")
            continue
        sv = ", ".join(f"{s:.3g}" for s in p.singular_values)
        print(f"{p.label}: rank {p.rank} of {n} (singular values {sv}), {p.determined} of {n} directions determined")
    messages = result.messages()
    print()
    for m in messages or ["Every parameter is determined on its own."]:
        print(m)
    if n > 1:
        width = max(len(x) for x in result.names)
        col = max(7, min(18, width))
        print("\ncorrelation at the start values:")
        print(" " * (width + 2) + " ".join(f"{x[-col:]:>{col}}" for x in result.names))
        for name, row in zip(result.names, result.correlation):
            print(f"{name:>{width}}  " + " ".join(f"{v:>{col}.3f}" for v in row))
