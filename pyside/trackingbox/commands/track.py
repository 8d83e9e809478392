"""``trackingbox track``: run the tracking simulator over the spec's measurements."""
from __future__ import annotations

import argparse
import json
import logging
import sys
from datetime import datetime
from pathlib import Path
from typing import Any

from ..checkpoint import CheckpointFile
from ..errors import SpecError
from ..io import check_output, output_dir
from ..online.live import LiveSettings, track_live
from ..online.opcua import read_credentials
from ..report import write_track_report
from ..report.track import summary_tables
from ..spec import check_against_fmu, load_spec
from ..stages import track as stage
from ..stages.contract import settings_from_args
from ..view.server import BackgroundView, ViewSettings
from . import SUMMARIES
from ._args import add_library_option, number, with_libraries
from ._progress import Progress

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  trackingbox track case1/spec.toml
  trackingbox track case1/spec.toml --report case1/track --window validation
  trackingbox track case1/spec.toml --out case1/run --json
  trackingbox track case1/spec.toml --out case1/run --resume     # continue after an interruption
  trackingbox track case1/spec.toml --controllers continuous     # the box's laws inside the integrator
  trackingbox track case1/spec.toml --carry 0                    # re-initialise the integrator at every change
  trackingbox track case1/spec.toml --live opc.tcp://dcs:4840 --out case1/live   # online, over OPC UA

One parameter controller per [[pairs]] entry (setpoint: the measured tag; process
value: the twin's variable; output: the parameter, scaled 0-100 % onto its
bounds; gains from kp/ti or SIMC-tuned from gain and time_constant), state
compensation per [[states]] entry, start-up hold until [tracking] hold_until.
The run streams OUT/tracking.csv (measured, tracked and untracked values,
parameters, corrections, controller modes) and checkpoints OUT/checkpoint.json.
NRMSE = RMSE / measured range over the chosen window after the start-up hold.

--live subscribes to the spec's tags on an OPC UA server ([live] section: node
ids, auth, security; credentials from TRACKINGBOX_OPCUA_USER/_PASSWORD or
--credentials FILE, never from the spec), runs the twin one sample behind the
plant and writes the same files, plus OUT/live_measurements.csv (every sample
received); it reconnects after losing the server and reads back what it missed.
See docs/online.md.
"""


def register(subparsers: Any) -> None:
    """Add the ``track`` subcommand."""
    p = subparsers.add_parser(
        "track",
        help=SUMMARIES["track"],
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
    add_library_option(p, "track --controllers continuous compiles the twin with its parameters as inputs")
    p.add_argument("--controllers", choices=("discrete", "continuous"), default="discrete",
                   help="discrete (default): the controllers' exact discretisation, updated every sample; "
                        "continuous: the box's laws integrated with the twin by CVODE (needs [source]; "
                        "compiles the twin with its tracked parameters as inputs once, cached)")
    p.add_argument("--carry", type=number(ge=0), default=None, metavar="FRACTION",
                   help="discrete controllers on a model-exchange twin: carry the twin's integrator across a "
                        "change of a tracked parameter of at most FRACTION of its bound range (a correction "
                        "flow: of its compensator's gain times its level's range) instead of re-initialising "
                        "it (default 0.02); 0: re-initialise at every change, the restart path, closer to "
                        "the exact closed loop where the twin's parameters change often (scripts/bench_carry measures both)")
    p.add_argument("--checkpoint-every", type=number(ge=1, integer=True), default=200, metavar="N",
                   help="rows between checkpoints (default 200)")
    live = p.add_argument_group("online mode (OPC UA)")
    live.add_argument("--live", metavar="URL", help="track live: subscribe to the tags at opc.tcp://HOST:PORT")
    live.add_argument("--credentials", type=Path, metavar="FILE",
                      help="file with 'user = ...' and 'password = ...' lines (mode 600) for [live] auth = \"user\"")
    live.add_argument("--live-from", metavar="ISO",
                      help="plant time (ISO 8601) to track from; earlier samples are read from the server's history")
    live.add_argument("--stop-after", type=float, metavar="SECONDS",
                      help="stop once the row at SECONDS of plant time is done (default: run until interrupted)")
    live.add_argument("--idle-timeout", type=float, metavar="SECONDS",
                      help="stop after SECONDS of wall-clock time without a new sample")
    live.add_argument("--view", metavar="HOST:PORT",
                      help="serve the live web view of the run at HOST:PORT (e.g. 127.0.0.1:8050; see "
                           "`trackingbox view`); off loopback it needs --view-credentials")
    live.add_argument("--view-credentials", type=Path, metavar="FILE",
                      help="'user = ...' and 'password = ...' lines (mode 600) the view asks for")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the tracking simulator; exit code 0 on success."""
    spec = with_libraries(load_spec(args.spec), args.library)
    inputs = [spec.path, spec.twin, spec.measurements]
    out = check_output(args.out or args.report or Path(spec.path).parent / "track",
                       "--out" if args.out else "--report" if args.report else "the output directory",
                       kind="dir", inputs=inputs)
    if (args.view or args.view_credentials) and not args.live:
        raise SpecError("--view goes with --live; for an offline run: trackingbox view OUT")
    if args.live:
        if args.controllers != "discrete" or args.carry is not None:
            if args.carry is not None:
                raise SpecError("--carry is not available with --live (the online mode steps its twins "
                                "with the default carry)")
            raise SpecError("--controllers continuous is not available with --live (the online mode steps the "
                            "discrete controllers sample by sample as the data arrive)")
        return _run_live(args, spec, out)
    if args.carry is not None and args.controllers != "discrete":
        raise SpecError("--carry applies to the discrete controllers: with --controllers continuous the "
                        "parameters move inside the integrator and there is nothing to carry")
    if args.report:
        check_output(args.report, "--report", kind="dir", inputs=inputs)
    if args.resume and (out / "checkpoint.json").exists():  # a damaged one is refused before anything runs
        CheckpointFile(out / "checkpoint.json", out / "tracking.csv").read()
    check_against_fmu(spec)  # before the output directory exists
    with output_dir(out), output_dir(args.report or out):
        settings = settings_from_args(stage.TrackSettings, args, out_dir=out,
                                      carry=stage.CARRY_FRACTION if args.carry is None else args.carry)
        result = stage.run(spec, settings, progress=Progress())
        if args.report:
            write_track_report(spec, result, args.report)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        _print_summary(result, {p.variable: p.parameter for p in spec.pairs})
        if args.report:
            print(f"report in {args.report}")
    return 0


def _run_live(args: argparse.Namespace, spec: Any, out: Path) -> int:
    start = None
    if args.live_from:
        try:
            start = datetime.fromisoformat(args.live_from)
        except ValueError:
            raise SpecError(f"--live-from {args.live_from!r} is not an ISO 8601 time") from None
    settings = LiveSettings(args.live, credentials=read_credentials(args.credentials), start=start,
                            stop_after=args.stop_after, idle_timeout=args.idle_timeout)
    view = None
    if args.view:
        out.mkdir(parents=True, exist_ok=True)
        view = BackgroundView(out, ViewSettings(bind=args.view, spec=Path(spec.path),
                                                credentials=args.view_credentials))
        print(f"live view at {view.url}", file=sys.stderr, flush=True)
    try:
        live = track_live(spec, settings, out_dir=out, resume=args.resume,
                          progress=Progress().counter("tracking", unit="row"))
    finally:
        if view is not None:
            view.close()
    if args.report:
        write_track_report(spec, live.tracking, args.report)
    if args.json:
        print(json.dumps(live.to_json(), indent=2))
    else:
        _print_summary(live.tracking, {p.variable: p.parameter for p in spec.pairs})
        print(f"live: {live.samples} samples ({live.backfilled} read back from history), "
              f"{live.connections} connection(s), origin {live.origin.isoformat()}")
    return 0


def _print_summary(result: Any, paired: dict[str, str] | None = None) -> None:
    print(summary_tables(result, paired).markdown())
    state = "complete" if result.complete else "stopped early (resume to continue)"
    print(f"{result.steps} rows, {result.simulated_seconds:g} s simulated in {result.seconds:.1f} s; {state}")
    print(f"trajectory: {result.csv}")
