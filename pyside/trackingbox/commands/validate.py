"""``trackingbox validate``: run the generated tracked FMU on held-out data and compare."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ..errors import TrackingError
from ..io import check_output, output_dir
from ..report import write_validate_report
from ..spec import load_spec
from ..stages import validate as stage
from ..stages.contract import settings_from_args
from . import SUMMARIES
from ._args import number

EPILOG = """\
examples:
  trackingbox validate case1/spec.toml --fmu case1/generated/TwinTracked.fmu
  trackingbox validate case1/spec.toml --fmu case1/generated/TwinTracked.fmu --json
  trackingbox validate case1/spec.toml --fmu case1/generated/TwinTracked.fmu --report case1/validate

Runs, from the first sample to the end of the spec's validation window: the
tracked FMU (measurements as inputs), the untracked twin and the Python tracking
runtime. Scores on the validation window: NRMSE (untracked, tracked FMU, Python),
time to converge (error within --band x span, span = |gain| (max - min)),
parameter trajectories within bounds, and the agreement of the Modelica box with
the Python runtime, max |p_modelica - p_python| / (max - min).
"""


def register(subparsers: Any) -> None:
    """Add the ``validate`` subcommand."""
    p = subparsers.add_parser(
        "validate",
        help=SUMMARIES["validate"],
        description="Validate a tracked FMU made by `trackingbox generate --compile` on held-out data.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml with [[pairs]] and a validation window")
    p.add_argument("--fmu", type=Path, required=True, help="the tracked FMU (<Twin>Tracked.fmu)")
    p.add_argument("--report", type=Path, default=None, metavar="DIR",
                   help="write validation.md, PNG plots and validation.csv into DIR")
    p.add_argument("--band", type=number(gt=0), default=0.05,
                   help="convergence band as a fraction of the variable's span (default 0.05)")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Validate; print a summary (or JSON)."""
    if not (args.band > 0.0 and math.isfinite(args.band)):
        raise TrackingError(f"--band must be a positive number, got {args.band}")
    spec = load_spec(args.spec)
    if args.report is not None:
        check_output(args.report, "--report", kind="dir", inputs=[spec.path, spec.twin, spec.measurements, args.fmu])
    with output_dir(args.report or "."):
        return _run(args, spec)


def _run(args: argparse.Namespace, spec: Any) -> int:
    result = stage.run(spec, settings_from_args(stage.ValidateSettings, args))
    report = None
    if args.report is not None:
        report = write_validate_report(spec, result, args.fmu, args.report).markdown
    if args.json:
        doc = result.to_json()
        if report is not None:
            doc["report"] = str(report)
        print(json.dumps(doc, indent=2))
        return 0
    print(f"validation window {result.window[0]:g}..{result.window[1]:g} s")
    for tag, v in result.variables.items():
        conv = "not converged" if v.converged_at is None else f"converged at {v.converged_at:.0f} s"
        print(f"  {tag}: NRMSE untracked {v.nrmse_untracked:.4g}, tracked (FMU) {v.nrmse_tracked:.4g}, "
              f"Python {v.nrmse_python:.4g}; {conv}")
    for name, p in result.parameters.items():
        print(f"  {name}: final {p.final:.6g} (Python {p.final_python:.6g}), range [{p.min:.6g}, {p.max:.6g}]"
              f"{'' if p.within_bounds else ' OUT OF BOUNDS'}, agreement {p.agreement:.3g}")
    print(f"agreement (max |p_modelica - p_python| / range): {result.agreement:.3g}")
    if report is not None:
        print(f"report: {report}")
    return 0
