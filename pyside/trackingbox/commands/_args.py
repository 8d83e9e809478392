"""Argument parsing shared by the commands: ``NAME=VALUE`` options (``--set``, ``--freeze``)."""
from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..errors import TrackingError


def parse_assignments(items: Iterable[str], option: str = "--set") -> dict[str, float]:
    """``["hx.kht=900", "hold=true"]`` -> ``{"hx.kht": 900.0, "hold": 1.0}``.

    ``true``/``false`` count as 1/0. Raises :class:`TrackingError` naming the
    option and the bad item (no ``=``, no name, not a finite number, a name given twice).

    >>> parse_assignments(["a=1", " b = 2.5 ", "c=false"])
    {'a': 1.0, 'b': 2.5, 'c': 0.0}
    """
    values: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name or not text:
            raise TrackingError(f"{option} {item!r}: expected NAME=VALUE, e.g. {option} hx.kht=900")
        try:
            value = float(text)
        except ValueError:
            if text.lower() not in ("true", "false"):
                raise TrackingError(f"{option} {item!r}: value {text!r} is not a number") from None
            value = 1.0 if text.lower() == "true" else 0.0
        if not math.isfinite(value):
            raise TrackingError(f"{option} {item!r}: value must be finite")
        if name in values:
            raise TrackingError(f"{option} {name!r} is given twice")
        values[name] = value
    return values


def number(*, gt: float | None = None, ge: float | None = None, le: float | None = None,
           integer: bool = False) -> Callable[[str], Any]:
    """An argparse ``type=``: a finite number (an integer with *integer*) in the given range.

    argparse turns the refusal into ``error: argument --step: must be > 0, got '0'`` and exit 2.

    >>> number(gt=0)("2.5"), number(ge=1, integer=True)("3")
    (2.5, 3)
    >>> number(gt=0)("nan")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: must be a finite number > 0, got 'nan'
    """
    kind = "an integer" if integer else "a finite number"
    limits = [f"{op} {v:g}" for op, v in ((">", gt), (">=", ge), ("<=", le)) if v is not None]
    wanted = kind + (" " + " and ".join(limits) if limits else "")

    def parse(text: str) -> Any:
        try:
            value: Any = int(text, 10) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {wanted}, got {text[:40]!r}") from None
        if not integer and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be {wanted}, got {text[:40]!r}")
        if ((gt is not None and not value > gt) or (ge is not None and not value >= ge)
                or (le is not None and not value <= le)):
            raise argparse.ArgumentTypeError(f"must be {wanted}, got {text[:40]!r}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


def scheduler_address(text: str) -> str:
    """An argparse ``type=`` for ``--scheduler``: ``local`` or a Dask scheduler address.

    The address has a host and a port (``tcp://10.0.0.5:8786``, ``tls://host:8786`` or
    ``host:8786``); anything else is refused before any work (exit 2).

    >>> scheduler_address("tcp://10.0.0.5:8786"), scheduler_address("local")
    ('tcp://10.0.0.5:8786', 'local')
    >>> scheduler_address("10.0.0.5")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected 'local' or a Dask scheduler address tcp://HOST:PORT, got '10.0.0.5'
    """
    text = text.strip()
    if text == "local":
        return text
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    host, colon, port = rest.rpartition(":")
    if scheme not in ("tcp", "tls", "inproc", "ucx", "ws", "wss") or not colon or not host or not port.isdigit() \
            or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(
            f"expected 'local' or a Dask scheduler address tcp://HOST:PORT, got {text[:80]!r}")
    return text


def add_executor_arguments(parser: argparse.ArgumentParser, *, what: str, default: str) -> None:
    """``--workers N`` and ``--scheduler ADDRESS|local``: where a stage's parallel runs go.

    Without ``--scheduler`` the runs go to N local worker processes (a process pool;
    1: this process). ``--scheduler local`` starts a Dask cluster of N single-threaded
    workers on 127.0.0.1 for the command; ``--scheduler tcp://HOST:PORT`` uses an
    existing Dask cluster (its workers must see the FMU under the same path).
    See :func:`trackingbox.analysis.executor.make_executor`.
    """
    parser.add_argument("--workers", type=number(ge=1, le=256, integer=True), default=None, metavar="N",
                        help=f"{what} in N local worker processes (default: {default}); with --scheduler "
                             "local, the Dask cluster's number of workers")
    parser.add_argument("--scheduler", type=scheduler_address, default=None, metavar="ADDRESS",
                        help="run them on a Dask cluster instead: tcp://HOST:PORT of an existing scheduler "
                             "(workers must see the FMU under the same path), or 'local' for a Dask "
                             "cluster of --workers processes on 127.0.0.1")


def add_library_option(p: argparse.ArgumentParser, what: str) -> None:
    """``--library PATH`` (repeatable): a Modelica library the twin's source uses, for *what*."""
    p.add_argument("--library", action="append", default=[], type=Path, metavar="PATH",
                   help=f"Modelica library the twin's source uses when {what} (package directory or .mo file; "
                        "repeatable), beside the spec's [source] libraries; libraries beside the source and "
                        "on MODELICAPATH are found without")


def with_libraries(spec: Any, libraries: Iterable[Any]) -> Any:
    """*spec* with *libraries* (``--library``) added to its ``[source] libraries`` (unchanged without)."""
    extra = tuple(Path(p).resolve() for p in libraries)
    if not extra or spec.source is None:
        return spec
    return replace(spec, source=replace(spec.source, libraries=tuple(dict.fromkeys((*spec.source.libraries,
                                                                                     *extra)))))
