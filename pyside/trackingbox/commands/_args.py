"""Argument parsing shared by the commands: ``NAME=VALUE`` options (``--set``, ``--freeze``)."""
from __future__ import annotations

import math
from collections.abc import Iterable

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
