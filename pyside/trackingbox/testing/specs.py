"""The spec of a one-input, one-output, one-parameter twin, as tests and the fuzz script write it.

Several tests (tracking, the watchdog, the spec fuzzer) and ``scripts/fuzz``
need the same small case: a twin with an input ``u`` fed from tag ``FI``, an
output ``y`` measured as ``TI`` and one estimated parameter ``k``. They differ
only in numbers and in which optional sections they carry; this writes them all.
"""
from __future__ import annotations

from collections.abc import Mapping

__all__ = ["first_order_spec"]


def _toml(value: object) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value)


def first_order_spec(*, twin: str = "twin.fmu", start: float, lower: float, upper: float,
                     training: tuple[float, float], validation: tuple[float, float],
                     fixed: Mapping[str, float] | None = None, pair: Mapping[str, object] | None = None,
                     hold_until: float | None = None, extra: str = "") -> str:
    """The spec's TOML text.

    Parameters
    ----------
    twin
        The twin FMU's path as written in the spec.
    start, lower, upper
        Start value and bounds of the parameter ``k``.
    training, validation
        The estimation windows (seconds).
    fixed
        A ``[fixed]`` section (name -> value), if given.
    pair
        The keys of one ``[[pairs]]`` entry pairing ``TI`` with ``k`` (``gain``,
        ``time_constant``, ...), if given.
    hold_until
        ``[tracking] hold_until``, if given.
    extra
        TOML text placed after the windows (e.g. a ``[data]`` section).
    """
    lines = [f"twin = {_toml(twin)}", 'measurements = "measurements.csv"', "sample_time = 10.0", "",
             "[inputs]", '"FI" = "u"', "", "[outputs]", '"TI" = "y"', "",
             "[[parameters]]", 'name = "k"', f"start = {start!r}", f"min = {lower!r}", f"max = {upper!r}", ""]
    if fixed:
        lines += ["[fixed]", *(f"{k} = {v!r}" for k, v in fixed.items()), ""]
    lines += ["[windows]", f"training = {_toml(training)}", f"validation = {_toml(validation)}", ""]
    if extra:
        lines += [extra.strip("\n"), ""]
    if pair:
        lines += ["[[pairs]]", 'variable = "TI"', 'parameter = "k"', *(f"{k} = {_toml(v)}" for k, v in pair.items()),
                  ""]
    if hold_until is not None:
        lines += ["[tracking]", f"hold_until = {hold_until!r}", ""]
    return "\n".join(lines)
