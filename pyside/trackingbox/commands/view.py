"""``trackingbox view OUT``: the live web view of a tracking run's output folder (running or finished)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..view.browser import Browser
from ..view.server import BackgroundView, ViewSettings, run_view
from . import SUMMARIES

EPILOG = """\
examples:
  trackingbox view case1/live                          # http://127.0.0.1:8050/
  trackingbox view case1/live --bind 127.0.0.1:9000
  trackingbox view case1/live --bind 0.0.0.0:8050 --credentials view.txt   # off loopback: basic auth
  trackingbox view case1/live --screenshot view.png    # a headless Chromium's picture of the page

The page shows, per tracked parameter, its trajectory (the plant's truth from
the bench's truth.json and the uncertainty band where tracking.csv has one),
per paired tag the measured, tracked and untracked values, each loop's state
(tracking, held, saturated) and why, every tag's staleness, the time since the
last sample and the run's health (reconnects, back-fills, rows written). It
updates by itself (server-sent events) and needs no internet. See docs/online.md.
"""


def register(subparsers: Any) -> None:
    """Add the ``view`` subcommand."""
    p = subparsers.add_parser(
        "view",
        help=SUMMARIES["view"],
        description="Serve a web page that follows a tracking run as its output folder grows.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("out", type=Path, help="the run's output folder (track --out)")
    p.add_argument("--bind", default="127.0.0.1:8050", metavar="HOST:PORT",
                   help="address to serve on (default 127.0.0.1:8050; port 0: any free port); "
                        "off loopback credentials are required")
    p.add_argument("--spec", type=Path, help="the run's spec (default: the one its checkpoint names)")
    p.add_argument("--credentials", type=Path, metavar="FILE",
                   help="'user = ...' and 'password = ...' lines (mode 600): HTTP basic auth "
                        "(or TRACKINGBOX_VIEW_USER/_PASSWORD)")
    p.add_argument("--certificate", type=Path, metavar="PEM", help="serve HTTPS with this certificate")
    p.add_argument("--private-key", type=Path, metavar="PEM", help="the certificate's private key")
    p.add_argument("--screenshot", type=Path, metavar="PNG",
                   help="take a picture of the page with headless Chromium and stop")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted (or take the screenshot); exit code 0."""
    settings = ViewSettings(bind=args.bind, spec=args.spec, credentials=args.credentials,
                            certificate=args.certificate, private_key=args.private_key)
    if args.screenshot is not None:
        with BackgroundView(args.out, settings) as view, Browser() as browser:
            page = browser.open(view.url)
            page.wait_for("document.body.dataset.updated !== undefined && Number(document.body.dataset.rows) >= 0")
            page.settle()
            page.screenshot(args.screenshot)
        print(f"screenshot of {view.url} in {args.screenshot}")
        return 0

    def ready(url: str) -> None:
        print(f"live view of {args.out} at {url} (Ctrl-C stops it)", file=sys.stderr, flush=True)

    run_view(args.out, settings, ready)
    return 0
