"""``trackingbox compile``: Modelica source → FMU."""
from __future__ import annotations

import argparse
import json

from ..compiler import BACKENDS, compile_model
from ..io import check_output, user_path
from . import SUMMARIES

EPILOG = """\
examples:
  trackingbox compile modelica/TrackingBox --model TrackingBox.Benches.HeatExchanger.Twin -o twin.fmu
  trackingbox compile plant.mo --model Plant --backend embedded --json

backends:
  auto          openmodelica where omc is on PATH, else embedded
  embedded      rumoca + CasADi + gcc, FMI 3.0 model exchange; PyPI packages only
  openmodelica  OMPython + omc, FMI 2.0 (model exchange and co-simulation)
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compile", help=SUMMARIES["compile"],
        description="Compile a Modelica class into an FMU.", epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("source", help=".mo file or Modelica package directory")
    p.add_argument("--model", required=True, help="full class name, e.g. Pkg.Sub.Model")
    p.add_argument("--backend", choices=BACKENDS, default="auto")
    p.add_argument("-o", "--output", help="FMU to write (default: <Model>.fmu here)")
    p.add_argument("--library", action="append", default=[], metavar="DIR",
                   help="further Modelica package directory the source uses (repeatable)")
    p.add_argument("--spec", metavar="SPEC",
                   help="check that the FMU exposes this spec's parameters (tunable), inputs and outputs "
                        "under the same names; a difference is an error naming each variable")
    p.add_argument("--parameters", choices=("tunable", "fixed"), default="tunable",
                   help="embedded backend: export the parameters tunable (default) or declare them 'fixed' "
                        "(set only before initialisation), as other tools export them")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    source = user_path(args.source, "source")
    if args.output is not None:
        check_output(args.output, "-o", inputs=[source])
    expected = None
    if args.spec:  # the spec reader imports the FMU stack (pandas, FMPy): only when asked for
        from ..compiler.omc_interface import ExpectedInterface
        from ..spec import load_spec

        expected = ExpectedInterface.from_spec(load_spec(args.spec, check_files=False))
    result = compile_model(args.source, args.model, backend=args.backend, output=args.output,
                           libraries=args.library, expected=expected, parameters=args.parameters)
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        print(f"{result.fmu}  (FMI {result.fmi_version}, {result.backend}, {result.states} states, "
              f"{result.parameters} {args.parameters} parameters, {result.seconds:.2f} s)")
    return 0
