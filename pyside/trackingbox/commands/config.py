"""``trackingbox config``: list the settings read from the environment, their values and where each comes from."""
from __future__ import annotations

import argparse
import json
from typing import Any

from .. import config
from . import SUMMARIES

EPILOG = """\
examples:
  trackingbox config
  trackingbox config --json
  TRACKINGBOX_NATIVE=0 trackingbox config

Each setting is read from its environment variable (TRACKINGBOX_<NAME>); an unset
or empty variable leaves the default. A value a setting does not take is an error
naming the variable (exit 2), here and in every other command.
"""


def register(subparsers: Any) -> None:
    """Add the ``config`` subcommand."""
    p = subparsers.add_parser(
        "config",
        help=SUMMARIES["config"],
        description="List trackingbox's settings read from the environment.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.set_defaults(func=run)


def _shown(record: dict[str, Any]) -> str:
    value = record["value"]
    if isinstance(value, bool):
        return "true" if value else "false"
    return "" if value is None else str(value)


def run(args: argparse.Namespace) -> int:
    records = config.describe()
    if args.json:
        print(json.dumps({"settings": records}, indent=2))
    else:
        header = ["name", "value", "source", "variable", "what it does"]
        rows = [[r["name"], _shown(r), r["source"], r["env"], r["doc"] + (" (internal)" if r["internal"] else "")]
                for r in records]
        widths = [max(len(header[i]), *(len(row[i]) for row in rows)) for i in range(4)]
        print("  ".join(h.ljust(w) for h, w in zip(header, widths)) + "  " + header[4])
        for row in rows:
            print("  ".join(c.ljust(w) for c, w in zip(row, widths)) + "  " + row[4])
    config.check_all()  # an invalid variable: listed above, then the one error line and exit 2
    return 0
