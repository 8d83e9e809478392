"""``trackingbox replay``: serve a bench case's measurements over OPC UA as a simulated DCS."""
from __future__ import annotations

import argparse
import json
import logging
import math
from datetime import datetime
from pathlib import Path
from typing import Any

from ..errors import SpecError
from ..online.opcua import read_users
from ..online.replay import ReplaySettings, replay
from . import SUMMARIES

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  trackingbox replay case1 --serve opc.tcp://127.0.0.1:4840
  trackingbox replay case1 --serve opc.tcp://127.0.0.1:4840 --speed 60     # an hour a minute
  trackingbox replay case1 --serve opc.tcp://127.0.0.1:4840 --users users.txt \\
      --certificate server.der --private-key server.pem                   # users only, Basic256Sha256

Every tag of CASE/spec.toml is the Double variable ns=2;s=<tag> (object Plant),
written row by row at origin + t/speed with source timestamp origin + t, and
historized (a client that lost the link reads back what it missed). A server
restarted with the same --origin puts the rows that fell due meanwhile into its
history and goes on: nothing is lost. --users FILE: 'user:password' lines (mode
600); anonymous sessions are then refused.
"""


def register(subparsers: Any) -> None:
    """Add the ``replay`` subcommand."""
    p = subparsers.add_parser(
        "replay",
        help=SUMMARIES["replay"],
        description="Serve a case's measurements as OPC UA variables, in real time or faster.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("case", type=Path, help="bench case directory (spec.toml, measurements.csv) or its spec.toml")
    p.add_argument("--serve", required=True, metavar="URL", help="endpoint to listen on, opc.tcp://HOST:PORT")
    p.add_argument("--speed", type=float, default=1.0, help="plant seconds per second (default 1: real time)")
    p.add_argument("--origin", metavar="ISO|+SECONDS",
                   help="wall-clock time of the case's first row, or +SECONDS after the server is ready "
                        "(default: now); the log line 'serving ...' gives it, for a restart")
    p.add_argument("--users", type=Path, metavar="FILE", help="'user:password' lines; refuse anonymous sessions")
    p.add_argument("--certificate", type=Path, metavar="FILE", help="server certificate (Basic256Sha256 only)")
    p.add_argument("--private-key", type=Path, metavar="FILE", help="the certificate's private key (PEM)")
    p.add_argument("--stop-after", type=float, metavar="SECONDS", help="serve only this many plant seconds")
    p.add_argument("--linger", type=float, default=math.inf, metavar="SECONDS",
                   help="keep serving this long after the last row (default: until interrupted)")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout at the end")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Serve until the case ends (and --linger passes) or Ctrl-C; exit code 0."""
    origin: datetime | float | None = None
    if args.origin and args.origin.startswith("+"):
        try:
            origin = float(args.origin[1:])
        except ValueError:
            origin = math.nan
        if not (math.isfinite(origin) and origin >= 0):
            raise SpecError(f"--origin {args.origin!r}: +SECONDS must be a finite number >= 0")
    elif args.origin:
        try:
            origin = datetime.fromisoformat(args.origin)
        except ValueError:
            raise SpecError(f"--origin {args.origin!r} is not an ISO 8601 time or +SECONDS") from None
    if (args.certificate is None) != (args.private_key is None):
        raise SpecError("--certificate and --private-key go together")
    if not (args.linger >= 0):
        raise SpecError(f"--linger must be >= 0, got {args.linger!r}")
    settings = ReplaySettings(speed=args.speed, origin=origin, users=read_users(args.users) if args.users else None,
                              certificate=args.certificate, private_key=args.private_key,
                              stop_after=args.stop_after, linger=args.linger)
    try:
        result = replay(args.case, args.serve, settings)
    except KeyboardInterrupt:
        log.info("stopped by the user")
        return 0
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
    else:
        print(f"served {result.rows} rows of {len(result.tags)} tags at {result.url} "
              f"({result.history_rows} into the history at start)")
    return 0
