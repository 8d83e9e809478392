"""Record values in the flat translation (issue 35: Modelica.Media's ``ThermodynamicState``).

The flat model has no record variables, only their fields (``valve1.state_a.p``); the front end
expands a record input of a function into one input per field and passes ``f(r).p`` for each.
What remains is a record *value*: a record constructor's result, a function's record output, a
record variable used whole (``state_a = Medium.setState_phX(...)``). Such a value is a
:class:`Record`, its fields by name. Inside an inlined function a record is kept field by field
in the environment (``s.p``, ``s.T``), so a field assignment ``s.p := u`` and the merge of
if-branches treat its fields as plain variables; :func:`store` and :func:`gather` convert.
An equation between two records is one equation per field (MLS 10.6.3 for the arrays of a
field): :func:`difference`.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from . import arrays as arr

Value = Any


class Record(dict):
    """A record's value: field name -> Value (a nested record is a :class:`Record`)."""


def store(name: str, value: Record, env: dict[str, Value]) -> None:
    """Put the fields of *value* into *env* as ``name.field`` (nested records further down);
    a stale whole-record entry under *name* is dropped."""
    env.pop(name, None)
    for field, val in value.items():
        if isinstance(val, Record):
            store(f"{name}.{field}", val, env)
        else:
            env[f"{name}.{field}"] = val


def gather(name: str, keys: Iterable[str], get: Callable[[str], Value]) -> Record | None:
    """The record whose fields are the *keys* under ``name.`` (values by *get*), or None when no
    key is under it."""
    prefix = name + "."
    fields: dict[str, list[str]] = {}
    for key in keys:
        if key.startswith(prefix):
            rest = key[len(prefix):]
            fields.setdefault(rest.split(".", 1)[0], []).append(key)
    if not fields:
        return None
    out = Record()
    for field, members in fields.items():
        full = prefix + field
        out[field] = get(full) if full in members else gather(full, members, get)
    return out


def is_record_array(value: Value) -> bool:
    """Whether *value* is an array of records (an object array of :class:`Record`, .record_arrays)."""
    return isinstance(value, np.ndarray) and value.size > 0 and isinstance(value.flat[0], Record)


def combine(size: tuple[int, ...], values: list[Value], what: str) -> np.ndarray:
    """The array of *size* whose elements (in order) are *values*: records, or values of one size
    (then the result's size is *size* followed by theirs)."""
    if any(isinstance(v, Record) for v in values):
        if not all(isinstance(v, Record) for v in values):
            raise RecordError(f"elements of {what} that are not all records")
        inner: tuple[int, ...] = ()
    else:
        sizes = {arr.shape(v) for v in values}
        if len(sizes) > 1:
            raise RecordError(f"elements of different sizes in {what}")
        inner = sizes.pop() if sizes else ()
    out = arr.new(size + inner)
    for pos, v in zip(np.ndindex(*size), values):
        out[pos] = v
    return out


def field_of_each(value: np.ndarray, field: str, what: str) -> np.ndarray:
    """``a.f`` for an array of records *a*: the array of each element's field *f* (MLS 10.6.3)."""
    missing = [r for r in value.ravel() if field not in r]
    if missing:
        raise RecordError(f"an element of {what} has no field {field!r} (fields: {', '.join(missing[0])})")
    return combine(value.shape, [r[field] for r in value.ravel()], f"{what}.{field}")


def difference(lhs: Value, rhs: Value, what: str) -> list[Value]:
    """The residuals of ``lhs = rhs`` between two records, one per scalar of each field of *lhs*
    (by name, recursively); a field one side lacks is an error naming it. Between two arrays of
    records of one size, element by element (MLS 10.6.3)."""
    if is_record_array(lhs) or is_record_array(rhs):
        if not (is_record_array(lhs) and is_record_array(rhs)):
            raise RecordError(f"an equation between an array of records and a value that is not one in {what}")
        if lhs.shape != rhs.shape:
            raise RecordError(f"arrays of records of sizes {arr.size_text(lhs.shape)} and "
                              f"{arr.size_text(rhs.shape)} equated in {what}")
        out: list[Value] = []
        for pos in np.ndindex(*lhs.shape):
            out.extend(difference(lhs[pos], rhs[pos], f"{what}, element {list(i + 1 for i in pos)}"))
        return out
    if not isinstance(lhs, Record) or not isinstance(rhs, Record):
        side = "right" if isinstance(lhs, Record) else "left"
        raise RecordError(f"an equation between a record and a value that is not one ({side} side) in {what}")
    missing = [f for f in lhs if f not in rhs] + [f for f in rhs if f not in lhs]
    if missing:
        raise RecordError(f"records with different fields ({', '.join(missing)}) equated in {what}")
    out = []
    for field, a in lhs.items():
        b = rhs[field]
        if isinstance(a, Record) or isinstance(b, Record):
            out.extend(difference(a, b, f"{what}, field {field}"))
            continue
        out.extend(arr.elements([arr.map2(lambda x, y: x - y, a, b, f"field {field} of {what}", broadcast=False)]))
    return out


class RecordError(ValueError):
    """A record used where its shape does not fit (message names the place)."""
