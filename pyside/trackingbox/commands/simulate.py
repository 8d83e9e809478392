"""``trackingbox simulate``: run an FMU on an inputs table and write the outputs to CSV."""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from pathlib import Path
from typing import Any

from ..data import read_table
from ..errors import FMUError, TrackingError, did_you_mean
from ..fmu import check_values, read_info
from ..io import atomic_path, check_output
from ..simulation.models import open_model
from . import SUMMARIES
from ._args import number, parse_assignments

log = logging.getLogger(__name__)

#: most result rows a simulation may write (a row per --step): more is refused before the run
MAX_ROWS = 10_000_000

EPILOG = """\
examples:
  trackingbox simulate twin.fmu --inputs inputs.csv -o result.csv
  trackingbox simulate twin.fmu --inputs inputs.csv --set hx.kht=900 --stop 3600 --step 10 -o result.csv
  trackingbox simulate twin.fmu --set mHot_flow=2.5 --stop 600 --output ThOut --output TcOut -o result.csv

The inputs CSV has a `time` column (s or ISO 8601) and one column per FMU input,
named as in the FMU (`trackingbox inspect twin.fmu --causality input`); inputs
are interpolated linearly and held before the first and after the last sample.
Every FMU input needs a column or a --set value. Defaults: start = first input
time (else the FMU's default experiment, else 0); stop = last input time (else
the FMU's default experiment stop); step = the FMU's default step size, else
(stop - start) / 500. The result has `time` and every output (or the --output
names) and is written atomically: on any error nothing is written.
"""


def register(subparsers: Any) -> None:
    """Add the ``simulate`` subcommand."""
    p = subparsers.add_parser(
        "simulate",
        help=SUMMARIES["simulate"],
        description="Simulate an FMU (model exchange with CVODE, or co-simulation) and write a result CSV.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("fmu", type=Path, help="the .fmu file")
    p.add_argument("--inputs", type=Path, metavar="CSV", help="inputs table: time + one column per FMU input")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", dest="set_values",
                   help="parameter, state start value or constant input (repeatable)")
    p.add_argument("--start", type=number(), metavar="T0", help="start time in s")
    p.add_argument("--stop", type=number(), metavar="T1", help="stop time in s")
    p.add_argument("--step", type=number(gt=0), metavar="DT", help="output interval in s")
    p.add_argument("--output", action="append", metavar="NAME", dest="outputs",
                   help="variable to write (repeatable; default: every output)")
    p.add_argument("--interface", choices=("ModelExchange", "CoSimulation"),
                   help="FMI interface to use (default: model exchange if the FMU has it)")
    p.add_argument("--tolerance", type=number(ge=1e-12, le=0.5), default=1e-6,
                   help="relative solver tolerance (default 1e-6)")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="RESULT.csv", help="result CSV to write")
    p.add_argument("--json", action="store_true", help="print one JSON summary document on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Validate everything, simulate, write the CSV atomically; 0 on success."""
    settings = parse_assignments(args.set_values, "--set")
    check_output(args.out, "-o", inputs=[p for p in (args.fmu, args.inputs) if p is not None])
    info = read_info(args.fmu)
    names = {v.name for v in info.variables}
    where = f"FMU {args.fmu.name}"
    for name in settings:
        if name not in names:
            raise FMUError(f"--set: unknown variable {name!r} in {where}{did_you_mean(name, names)}")
    check_values(info, settings, "--set")
    for name in args.outputs or ():
        if name not in names:
            raise FMUError(f"--output: unknown variable {name!r} in {where}{did_you_mean(name, names)}")

    inputs = None
    fmu_inputs = info.inputs
    if args.inputs is not None:
        inputs = read_table(args.inputs, allow_nan=False, what="inputs")
        columns = [c for c in inputs.columns if c != "time"]
        unknown = [c for c in columns if c not in fmu_inputs]
        if unknown:
            listed = "; ".join(f"column {c!r} of {args.inputs.name} is not an input of {where}"
                               f"{did_you_mean(c, fmu_inputs)}" for c in unknown[:5])
            more = f" (and {len(unknown) - 5} more columns)" if len(unknown) > 5 else ""
            raise FMUError(listed + more)
        clash = [c for c in columns if c in settings]
        if clash:
            raise TrackingError(f"input(s) {', '.join(map(repr, clash))} are given both in "
                                f"{args.inputs.name} and with --set; use one")
    else:
        columns = []
    missing = [n for n in fmu_inputs if n not in columns and n not in settings]
    if missing:
        raise FMUError(f"{where} input(s) {', '.join(map(repr, missing))} have no values: add column(s) to "
                       f"{'the --inputs CSV' if args.inputs is None else args.inputs.name} or use --set NAME=VALUE")

    t_in = inputs["time"].to_numpy() if inputs is not None and len(inputs) else None
    start = args.start
    if start is None:
        start = float(t_in[0]) if t_in is not None else (info.start_time or 0.0)
    stop = args.stop
    if stop is None:
        if t_in is not None:
            stop = float(t_in[-1])
        elif info.stop_time is not None:
            stop = info.stop_time
        else:
            raise TrackingError(f"no stop time: give --stop (no --inputs and {where} has no default experiment)")
    if not stop > start:
        origin = "--start" if args.start is not None else \
            "the start time (the first input time)" if t_in is not None else "the start time (the FMU's default)"
        raise TrackingError(f"--stop {stop:g} s must be after {origin} {start:g} s")
    step = args.step
    if step is None:
        step = info.step_size if info.step_size else (stop - start) / 500.0
    if not (step > 0 and math.isfinite(step)):
        raise TrackingError(f"--step must be a positive number of seconds, not {step:g}")
    if step > stop - start:
        raise TrackingError(f"--step {step:g} s is longer than the run (--start {start:g} s to --stop {stop:g} s)")
    rows = (stop - start) / step
    if rows > MAX_ROWS:
        raise TrackingError(f"--stop {stop:g} with --step {step:g} asks for {rows:.3g} result rows "
                            f"(at most {MAX_ROWS:g}): give a larger --step or a shorter run")

    t0 = time.perf_counter()
    with open_model(args.fmu, tolerance=args.tolerance, interface=args.interface) as model:
        result = model.simulate(start_time=start, stop_time=stop, output_interval=step, inputs=inputs,
                                parameters=settings, outputs=args.outputs)
    seconds = time.perf_counter() - t0
    with atomic_path(args.out) as tmp:
        result.to_csv(tmp, index=False, float_format="%.12g")
    log.info("simulated %s from %g s to %g s in %.2f s; wrote %s", args.fmu, start, stop, seconds, args.out)
    if args.json:
        print(json.dumps({"fmu": str(args.fmu), "output": str(args.out), "start": start, "stop": stop,
                          "step": step, "rows": int(len(result)), "columns": list(result.columns),
                          "seconds": round(seconds, 4)}))
    else:
        print(f"wrote {args.out} ({len(result)} rows: {', '.join(result.columns)}) in {seconds:.2f} s",
              file=sys.stderr)
    return 0
