"""``trackingbox bench``: generate a bench case (plant, twin, noisy measurements, spec)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from ..benches import BENCHES, make_bench
from ..errors import TrackingError
from ..io import check_output
from . import SUMMARIES
from ._args import number, parse_assignments

EPILOG = """\
examples:
  trackingbox bench heat-exchanger --out case1
  trackingbox bench heat-exchanger --out case2 --seed 3 --set hx.kht=850 --hours 4
  trackingbox bench heat-production --out hp --json
  trackingbox bench heat-production --out leak --hidden leak-level --noise-scale 2
  trackingbox bench evaporator --out ev --days 3 --seed 1 --set RfInf=2e-4
  trackingbox bench evaporator --out ev-clean --days 1 --hidden clean
  trackingbox bench evaporator-train --out train --effects 7 --days 1
  trackingbox bench evaporator-train --out train-vent --effects 3 --hidden vent-orifice --noise-scale 2

writes into --out:
  plant.fmu, twin.fmu     the "physical" plant and the digital twin (FMUs)
  measurements.csv        time (s) + measured tags, with sensor noise
                          (0.1 K temperatures, 1 % flows, 5 mm levels)
  plant_inputs.csv        the plant's true (noise-free) inputs
  spec.toml               the tracking specification (training = first half,
                          validation = second half)
  truth.json              the true plant parameter values (the spec does not read it)

--set NAME=VALUE changes a plant parameter (the truth); unknown names and values
outside the parameter's declared min/max are errors. Nothing is written unless
the whole case could be generated.

evaporator: measurements.csv is a historian export (ISO 8601 timestamps,
per-tag sampling, dead-band reporting, communication losses); truth.json also
holds the plant's fouling resistance over time and the flow stoppages.
evaporator-train: the same for a train of --effects N effects (2..12, default 7;
default period 1 day); truth.json holds every effect's fouling over time.
"""


def register(subparsers: Any) -> None:
    """Add the ``bench`` subcommand."""
    p = subparsers.add_parser(
        "bench",
        help=SUMMARIES["bench"],
        description="Compile a bench's plant and twin from the shipped library, simulate the plant "
                    "through a seeded scenario, add sensor noise and write a ready-to-use case.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("bench", choices=sorted(BENCHES), help="which bench")
    p.add_argument("--out", "-o", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument("--seed", type=number(ge=0, integer=True), default=0,
                   help="seed of the scenario and the noise (default 0)")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   metavar="NAME=VALUE", help="plant parameter value (repeatable)")
    p.add_argument("--hours", type=number(gt=0), default=None,
                   help="measured period in hours (default 8 heat-exchanger, 24 heat-production, "
                        "72 evaporator, 24 evaporator-train)")
    p.add_argument("--days", type=number(gt=0), default=None,
                   help="measured period in days (instead of --hours; default 3 for the evaporator)")
    p.add_argument("--hidden", default=None, metavar="CASE",
                   help="simulate a plant variant with an effect the twin lacks (diagnose's suite; "
                        "heat-exchanger: fouling-exp, heat-loss, sensor-drift, sensor-lag, bypass; "
                        "heat-production: leak-level, fouling-exp, heat-loss, sensor-drift; evaporator: clean, vent-orifice, "
                        "shell-loss, flash-demister, borated-liquor, burkeite-scale, density-meter, foaming-flash, "
                        "demister-carryover, ncg-after-restart; evaporator-train: clean, vent-orifice, shell-loss, "
                        "vent-and-loss); truth.json says which")
    p.add_argument("--suite-twin", action=argparse.BooleanOptionalAction, default=None,
                   help="write the case against the bench's suite twin, the twin the hidden-effect suite "
                        "diagnoses against (heat-production: the twin with the plant's quadratic curves); "
                        "default: for --hidden cases only")
    p.add_argument("--effects", type=number(ge=2, le=12, integer=True), default=None, metavar="N",
                   help="evaporator-train: number of effects (default 7)")
    p.add_argument("--noise-scale", type=number(ge=0, le=1000), default=1.0, metavar="S",
                   help="factor on every sensor's noise (default 1)")
    p.add_argument("--plant-fmu", type=Path, default=None, help=argparse.SUPPRESS)
    p.add_argument("--twin-fmu", type=Path, default=None, help=argparse.SUPPRESS)
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.set_defaults(func=run)


#: longest bench case (hours): a year of one-second data
MAX_HOURS = 24.0 * 366


def run(args: argparse.Namespace) -> int:
    """Generate the case; print a summary (or JSON)."""
    overrides = parse_assignments(args.overrides, "--set")
    if args.hours is not None and not args.hours > 0:
        raise TrackingError(f"--hours must be > 0, got {args.hours:g}")
    if args.days is not None and not args.days > 0:
        raise TrackingError(f"--days must be > 0, got {args.days:g}")
    if args.days is not None and args.hours is not None:
        raise TrackingError("give --days or --hours, not both")
    hours = args.days * 24.0 if args.days is not None else args.hours
    if hours is not None and hours > MAX_HOURS:
        raise TrackingError(f"--{'days' if args.days is not None else 'hours'}: {hours:g} h is more than the "
                            f"{MAX_HOURS:g} h a bench case may span")
    check_output(args.out, "--out", kind="dir", inputs=[p for p in (args.plant_fmu, args.twin_fmu) if p])
    case = make_bench(args.bench, args.out, seed=args.seed, overrides=overrides, hours=hours,
                      plant_fmu=args.plant_fmu, twin_fmu=args.twin_fmu, hidden=args.hidden,
                      noise_scale=args.noise_scale, effects=args.effects, suite_twin=args.suite_twin)
    if args.json:
        json.dump(case.to_json(), sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        truth = ", ".join(f"{k} = {v:g}" for k, v in case.truth.items())
        print(f"wrote {case.name} case to {case.directory} ({case.hours:g} h, seed {case.seed})")
        print(f"  spec:         {case.spec}")
        print(f"  measurements: {case.measurements}")
        print(f"  truth:        {truth or '(none of the candidates exists in the plant)'}")
        print(f"next: trackingbox estimate {case.spec}")
    return 0
