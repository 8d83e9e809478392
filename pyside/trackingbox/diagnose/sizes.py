"""Effect-parameter bounds relative to the target component's size (``per`` of an effect entry).

An absolute bound (``max = 2000.0`` W/K of a shell's loss) holds for one size of unit only. A parameter
with ``per = "A"`` and ``per_range = [start, min, max]`` gets, on a target, those values per unit of the
target's parameter ``A`` (its heat-transfer area, say) times the target's value, read from the twin FMU:
the variable's start value, else its value after the FMU's initialisation (a parameter computed from
others, ``A = ADesign[k]``, has no start value). ``per`` may be a table ``{ "<class>" = "<parameter>" }``:
only targets of those classes (or subclasses) scale; the others keep the absolute ``start``/``min``/``max``.

A whole-array target (``effect``, one value on every element) gets ``min`` times the smallest element's
size and ``max`` times the largest's, so every element's own bound is inside.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import SpecError

__all__ = ["per_variable", "read_per", "read_sizes", "scaled"]


def read_per(table: Mapping[str, Any], label: str, problems: list[str]
             ) -> tuple[str | dict[str, str], tuple[float, float, float] | None]:
    """``per`` and ``per_range`` of an effect parameter's table (problems appended to *problems*)."""
    per, rng = table.get("per", ""), table.get("per_range")
    if per == "" and rng is None:
        return "", None
    ident = r"[A-Za-z_]\w*"
    ok = isinstance(per, str) and re.fullmatch(ident, per) or (
        isinstance(per, dict) and per and all(isinstance(v, str) and re.fullmatch(ident, v) for v in per.values()))
    if not ok:
        problems.append(f"{label}: field 'per' must name a parameter of the target (\"A\") or be a table "
                        f"class = parameter")
    if not (isinstance(rng, list) and len(rng) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                            and math.isfinite(x) for x in rng)
            and rng[1] < rng[2] and rng[1] <= rng[0] <= rng[2]):
        problems.append(f"{label}: with 'per', field 'per_range' must be [start, min, max] per unit of it, "
                        f"min < max and start inside")
        return "", None
    return (dict(per) if isinstance(per, dict) else per), (float(rng[0]), float(rng[1]), float(rng[2]))


def per_variable(per: str | Mapping[str, str], bases: Sequence[str]) -> str:
    """The target parameter the bounds are per unit of, for a target whose class has *bases* (itself
    first); "" when *per* is a table naming none of them."""
    if isinstance(per, str):
        return per
    for cls in bases:
        if cls in per:
            return per[cls]
    return ""


@functools.lru_cache(maxsize=8)
def _values(path: str, mtime_ns: int, names: tuple[str, ...]) -> tuple[float | None, ...]:
    from ..fmu import FMUModel, read_info

    info = {v.name: v for v in read_info(path).variables}
    out: list[float | None] = []
    missing: list[str] = []
    for n in names:
        v = info.get(n)
        if v is None:
            out.append(None)
            continue
        try:
            out.append(float(v.start) if v.start is not None else math.nan)
        except (TypeError, ValueError):
            out.append(None)
        if v.start is None:
            missing.append(n)
    if missing:  # computed parameters: their values after initialisation
        with FMUModel(path) as model:
            got = dict(zip(missing, model.stepper(start_time=0.0).get(missing)))
        out = [float(got[n]) if n in got else x for n, x in zip(names, out)]
    return tuple(out)


def read_sizes(fmu: str | Path, names: Sequence[str]) -> list[float | None]:
    """Values of the variables *names* of the twin FMU *fmu* (None where the FMU has no such variable)."""
    p = Path(fmu).resolve()
    return list(_values(str(p), p.stat().st_mtime_ns, tuple(names)))


def scaled(entry: str, parameter: str, target: str, variable: str, fmu: str | Path, elements: Sequence[str],
           per_bounds: tuple[float, float, float]) -> tuple[float, float, float]:
    """(start, min, max) of *parameter* of effect *entry* on *target*: *per_bounds* (start, min, max per
    unit of *variable*) times the target's *variable*, read for each of *elements* (the target, or every
    element of a whole-array target) from *fmu*. SpecError naming the entry, the parameter and the target
    when the twin has no such variable or its value is not a positive finite number."""
    names = [f"{e}.{variable}" for e in elements]
    where = (f"effect {entry!r}, parameter {parameter!r}: its bounds are per {variable!r} of the target, "
             f"but target {target!r}")
    if not names:
        raise SpecError(f"{where} has no elements in the twin FMU {fmu} to read {variable!r} from")
    try:
        values = read_sizes(fmu, names)
    except SpecError:
        raise
    except Exception as exc:  # noqa: BLE001 - an unreadable FMU is the spec's problem here
        raise SpecError(f"{where}: cannot read {', '.join(names)} from the twin FMU {fmu}: {exc}") from None
    bad = [n for n, v in zip(names, values) if v is None]
    if bad:
        raise SpecError(f"{where} has no {variable!r} ({', '.join(bad)} is not a variable of the twin FMU {fmu})")
    sizes = [float(v) for v in values if v is not None]
    if not all(math.isfinite(v) and v > 0 for v in sizes):
        raise SpecError(f"{where}: {variable!r} must be a positive number; the twin FMU {fmu} gives "
                        + ", ".join(f"{n} = {v!r}" for n, v in zip(names, sizes)))
    start, lo, hi = per_bounds
    small, large = min(sizes), max(sizes)
    lo_abs, hi_abs = lo * small, hi * large
    return float(min(max(start * small, lo_abs), hi_abs)), float(lo_abs), float(hi_abs)
