"""``trackingbox inspect``: show the interface of an FMU (variables, causality, bounds, units)."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from ..fmu import read_info
from . import SUMMARIES

EPILOG = """\
examples:
  trackingbox inspect twin.fmu
  trackingbox inspect twin.fmu --json
  trackingbox inspect twin.fmu --causality parameter --causality input

Internal variables of generated code (names starting with "__") and the
independent variable "time" are left out of the table; --all shows them.
"""

FIELDS = ("name", "causality", "variability", "start", "min", "max", "nominal", "unit", "description")


def register(subparsers: Any) -> None:
    """Add the ``inspect`` subcommand."""
    p = subparsers.add_parser(
        "inspect",
        help=SUMMARIES["inspect"],
        description="Show an FMU's FMI version, interfaces and variables.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("fmu", type=Path, help="the .fmu file")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--causality", action="append", metavar="KIND",
                   choices=("parameter", "calculatedParameter", "input", "output", "local", "independent",
                            "structuralParameter"),
                   help="only variables of this causality (repeatable)")
    p.add_argument("--all", action="store_true", help="also list 'time' and generated '__' variables")
    p.set_defaults(func=run)


def _json_value(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _table(rows: list[list[str]], header: list[str]) -> str:
    widths = [max(len(header[j]), *(len(r[j]) for r in rows)) if rows else len(header[j])
              for j in range(len(header))]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip(),
             "  ".join("-" * w for w in widths)]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Print the FMU's interface; 0 on success (FMUError otherwise, handled by the CLI)."""
    info = read_info(args.fmu)
    variables = [
        v for v in info.variables
        if (args.all or (v.causality != "independent" and not v.name.startswith("__")))
        and (not args.causality or v.causality in args.causality)
    ]
    if args.json:
        doc = {
            "fmi_version": info.fmi_version,
            "model_name": info.model_name,
            "interfaces": list(info.interfaces),
            "variables": [{f: _json_value(getattr(v, f)) for f in FIELDS} for v in variables],
        }
        print(json.dumps(doc, indent=2))
        return 0
    print(f"{info.path}: FMI {info.fmi_version}, model {info.model_name}, "
          f"{' + '.join(info.interfaces)}, {info.number_of_states} continuous state(s)")
    if info.stop_time is not None:
        print(f"default experiment: start {info.start_time or 0:g} s, stop {info.stop_time:g} s")
    print()
    rows = [[_cell(getattr(v, f)) for f in FIELDS] for v in variables]
    print(_table(rows, list(FIELDS)))
    return 0
