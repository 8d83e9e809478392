"""The ``trackingbox`` command line: one entry point with subcommands.

Each subcommand lives in ``trackingbox.commands.<name>`` and provides
``register(subparsers)`` (adds its parser and sets ``func``) and
``run(args) -> int``. A run imports only the module of the command it runs
(``trackingbox compile`` never loads pandas, SciPy's statistics or the FMU
simulation stack); the others are listed from :data:`~.commands.SUMMARIES`.
Errors that a user caused (:class:`TrackingError`) are printed as one line on
stderr with a non-zero exit and no traceback.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from types import ModuleType
from typing import NoReturn

from . import config
from .commands import SUMMARIES
from .config import ConfigError
from .errors import TrackingError
from .supervise import supervise
from .version import __version__

#: Subcommands, in the order ``--help`` lists them; each lives in ``trackingbox.commands.<name>``.
COMMANDS = tuple(SUMMARIES)

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


def command_module(name: str) -> ModuleType:
    """The module of the subcommand *name* (imported on first use: it imports its whole stage)."""
    return importlib.import_module(f".commands.{name}", __package__)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``trackingbox`` parser; with *command*, only that subcommand's module is imported.

    The other subcommands get a parser with their one-line help only (enough for
    ``trackingbox --help`` and for naming the valid choices); without *command*, every
    subcommand's module is imported and registered in full.
    """
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
        if command is None or name == command:
            command_module(name).register(sub)
        else:
            sub.add_parser(name, help=SUMMARIES[name])
    return parser


def _command_of(argv: list[str]) -> str | None:
    """The subcommand *argv* names: its first word not an option (the top-level options take no value)."""
    word = next((w for w in argv if not w.startswith("-")), None)
    return word if word in SUMMARIES else None


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
    words = sys.argv[1:] if argv is None else list(argv)
    try:
        args = build_parser(_command_of(words) or "").parse_args(words)
        if not hasattr(args, "func"):  # a command word _command_of did not see
            args = build_parser(args.command).parse_args(words)
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
