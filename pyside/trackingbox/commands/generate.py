"""``trackingbox generate`` (``gen-trackingbox``): Modelica tracking box and tracked model."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from ..io import check_output, output_dir
from ..spec import load_spec
from ..stages import generate as stage
from ..stages.contract import settings_from_args
from . import SUMMARIES

EPILOG = """\
examples:
  gen-trackingbox case1/spec.toml -o case1/generated
  trackingbox generate case1/spec.toml -o case1/generated --compile
  trackingbox generate case1/spec.toml -o gen --rewrite --json
  gen-trackingbox wall/spec.toml -o wall/generated --compile --library ../msl/Modelica

writes into -o DIR a Modelica package <Twin>Tracking/ (package.mo, package.order,
<Twin>TrackingBox.mo, <Twin>Tracked.mo) that loads together with the twin's
library; --compile also writes DIR/<Twin>Tracked.fmu. The spec needs [source]
(the twin's Modelica) and [[pairs]] (run `trackingbox pair` first).

Each tracked parameter's component must offer a conditional input
(parameter Boolean use_kht_in, input kht_in if use_kht_in). If a class of the
twin's own package does not, generate stops and prints the lines to add;
--rewrite instead writes a patched copy of the source to DIR/patched/ and
prints the unified diff. A component whose class lives in a read-only library
(the MSL, [source] libraries, --library) gets a variant of that class in the
generated package, and the tracked model extends a variant of the twin that
uses it: the library is never edited. A top-level parameter of the twin passed
to components by modifiers (thermalResistor1(R = R1)) is driven through each of
them. A parameter that cannot follow an input (Evaluate = true, used in another
parameter's binding or a start value) is refused, naming why.
"""


def register(subparsers: Any) -> None:
    """Add the ``generate`` subcommand."""
    p = subparsers.add_parser(
        "generate",
        help=SUMMARIES["generate"],
        description="Generate a Modelica package with a tracking box (one scaled PI parameter controller "
                    "per pair) and the twin augmented with it, from a spec with [source] and [[pairs]].",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml with [source] and [[pairs]]")
    p.add_argument("-o", "--out", type=Path, default=None, metavar="DIR",
                   help="output directory (default: 'generated' beside the spec)")
    p.add_argument("--compile", action="store_true", help="also compile the tracked model into an FMU")
    p.add_argument("--backend", choices=("auto", "embedded", "openmodelica"), default="auto",
                   help="compiler backend for --compile (default auto)")
    p.add_argument("--rewrite", action="store_true",
                   help="patch a copy of the twin's source where a component of its own lacks the conditional "
                        "input (a component of a library class gets a generated variant of it anyway)")
    p.add_argument("--library", action="append", default=[], type=Path, metavar="PATH",
                   help="Modelica library the twin uses (package directory or .mo file; repeatable), beside "
                        "[source] libraries; libraries beside the source and on MODELICAPATH are found without")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Generate (and optionally compile); print a summary or JSON."""
    spec = load_spec(args.spec, check_files=False)
    out = args.out if args.out is not None else spec.path.parent / "generated"
    inputs = [spec.path, spec.twin, spec.measurements, *([spec.source.path] if spec.source else [])]
    out = check_output(out, "-o" if args.out is not None else "the output directory", kind="dir", inputs=inputs)
    with output_dir(out):
        return _run(args, spec, out)


def _run(args: argparse.Namespace, spec: Any, out: Path) -> int:
    result = stage.run(spec, settings_from_args(stage.GenerateSettings, args, out_dir=out,
                                                library=tuple(args.library)))
    if result.rewrite is not None:
        # The diff is part of what the user asked for; keep stdout clean for --json.
        stream = sys.stderr if args.json else sys.stdout
        stream.write(result.rewrite.diff)
    compiled = stage.compile_generated(result, backend=args.backend) if args.compile else None
    if args.json:
        print(json.dumps({**result.to_json(), "compile": None if compiled is None else compiled.to_json()},
                         indent=2))
    else:
        print(f"wrote {result.package_dir} ({', '.join(f.name for f in result.files)})")
        for c in result.controllers:
            print(f"  {c.parameter} tracks {c.tag}: kp = {c.kp:.4g}, Ti = {c.ti:.4g} s, "
                  f"bounds [{c.p_min:g}, {c.p_max:g}]")
        if result.rewrite is not None:
            print(f"patched source: {result.rewrite.path}")
        if compiled is not None:
            print(f"compiled {result.tracked_model} -> {compiled.fmu}")
    return 0
