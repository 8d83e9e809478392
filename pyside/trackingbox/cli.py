"""The ``trackingbox`` command line: one entry point with subcommands.

Each subcommand lives in ``trackingbox.commands.<name>`` and provides
``register(subparsers)`` (adds its parser and sets ``func``) and
``run(args) -> int``. Errors that a user caused (:class:`TrackingError`) are
printed as one line on stderr with a non-zero exit and no traceback.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
from typing import NoReturn

from . import config
from .commands import (
    bench,
    diagnose,
    estimate,
    identify,
    generate,
    inspect,
    pair,
    replay,
    simulate,
    track,
    validate,
    view,
)
from .commands import compile as compile_command
from .commands import config as config_command
from .config import ConfigError
from .errors import TrackingError
from .supervise import supervise
from .version import __version__

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = (
    "compile",
    "inspect",
    "simulate",
    "bench",
    "pair",
    "identify",
    "estimate",
    "track",
    "replay",
    "view",
    "generate",
    "validate",
    "diagnose",
    "config",
)

#: Subcommand name -> its module.
MODULES = {"compile": compile_command, "inspect": inspect, "simulate": simulate, "bench": bench, "pair": pair,
           "identify": identify, "estimate": estimate, "track": track, "replay": replay, "generate": generate,
           "validate": validate, "view": view, "diagnose": diagnose, "config": config_command}

EPILOG = """\
examples:
  trackingbox compile modelica/TrackingBox --model TrackingBox.Benches.HeatExchanger.Twin -o twin.fmu
  trackingbox inspect twin.fmu --json
  trackingbox simulate twin.fmu --inputs inputs.csv --stop 3600 -o result.csv
  trackingbox bench heat-exchanger --out case1 --seed 3
  trackingbox identify case1/spec.toml
  trackingbox estimate case1/spec.toml --report case1/estimate
  trackingbox pair case1/spec.toml --method rga --report case1/pair
  trackingbox track case1/spec.toml --report case1/track
  gen-trackingbox case1/spec.toml -o case1/generated --compile
  trackingbox validate case1/spec.toml --fmu case1/generated/TwinTracked.fmu
  trackingbox diagnose case1/spec.toml --compile --report case1/diagnose -o case1/patched
  trackingbox config --json
"""


class UsageError(TrackingError):
    """A command line argparse refused (unknown option, a value out of range)."""


class _Parser(argparse.ArgumentParser):
    """argparse, with its refusals raised (one ``error:`` line from :func:`main`, exit 2), not printed."""

    def error(self, message: str) -> NoReturn:  # type: ignore[override]
        raise UsageError(f"{self.prog}: {message} (see {self.prog} --help)")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="trackingbox",
        description="Turn a Modelica process model (FMU) into a tracking simulator.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"trackingbox {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more log output on stderr (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        MODULES[name].register(sub)
    return parser


def _setup_logging(verbosity: int) -> None:
    level = logging.WARNING if verbosity <= 0 else logging.INFO if verbosity == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """The ``trackingbox`` command; with *argv* None (the console script) the run is supervised.

    Supervised: the command runs in a forked child while this process waits, so
    that foreign native code (an FMU's binary) that crashes, or calls ``exit()``,
    after :mod:`trackingbox.fmu`'s canary has passed still ends in one ``error:``
    line naming the signal and the FMI function, not in a bare exit 139
    (:func:`supervise`; ``TRACKINGBOX_SUPERVISE=0`` turns it off). Called with a
    list (tests, scripts), the command runs in this process.
    """
    try:
        config.check_all()  # a bad TRACKINGBOX_* value: one error line before anything runs
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if argv is None and config.get("supervise") and hasattr(os, "fork"):
        return supervise(_run, sys.argv[1:])
    return _run(argv)


def _run(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    _setup_logging(args.verbose)
    try:
        return int(args.func(args) or 0)
    except TrackingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # the system refused (disk full, permissions changed during the run)
        where = f"{_short(str(exc.filename))}: " if exc.filename else ""
        print(f"error: {args.command}: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"error: {args.command}: out of memory (the run needs more than this machine allows; "
              "shorten the data or the run)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


def _short(text: str, limit: int = 160) -> str:
    return text if len(text) <= limit else f"{text[:limit // 2]}...{text[-(limit // 2):]}"


def gen_trackingbox_main(argv: list[str] | None = None) -> int:
    """``gen-trackingbox SPEC ...``: the same as ``trackingbox generate SPEC ...``."""
    try:
        config.check_all()
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    arguments = sys.argv[1:] if argv is None else list(argv)
    if argv is None and config.get("supervise") and hasattr(os, "fork"):
        return supervise(_run, ["generate", *arguments])
    return _run(["generate", *arguments])


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
