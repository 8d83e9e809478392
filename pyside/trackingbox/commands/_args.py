"""Argument parsing shared by the commands: ``NAME=VALUE`` options (``--set``, ``--freeze``)."""
from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable
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
