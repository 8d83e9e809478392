"""Python values as Modelica literals, for the code-generation templates.

Every value that ends up in generated Modelica passes through one of these
functions (registered as Jinja filters by :func:`register`), so formatting
rules live in one tested place:

* ``modelica_real``: a finite float with ``repr`` precision that always reads as
  a Real literal (``1.0``, ``1e-05``, ``1e+20``), never ``inf``/``nan``;
* ``modelica_bool``: ``true``/``false``;
* ``modelica_array``: ``{1.0, 2.0}`` (nested sequences give matrices);
* ``modelica_string``: a double-quoted string literal with escapes;
* ``modelica_ident``: checks that a name is a valid Modelica identifier
  (not a keyword) and returns it unchanged;
* ``modelica_name``: a measurement tag or dotted parameter name turned into an
  identifier (``"TI-102"`` -> ``TI_102``, ``"hx.kht"`` -> ``hx_kht``).
"""
from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any

import jinja2

__all__ = [
    "MODELICA_KEYWORDS", "modelica_real", "modelica_bool", "modelica_array",
    "modelica_string", "modelica_ident", "modelica_name", "modelica_literal",
    "is_identifier", "modelica_unit_modifier", "modelica_points", "unit_quotient", "register",
]

#: Reserved words of Modelica 3.6 (section 2.3.3); none may be used as an identifier.
MODELICA_KEYWORDS = frozenset("""
algorithm and annotation block break class connect connector constant constrainedby
der discrete each else elseif elsewhen encapsulated end enumeration equation expandable
extends external false final flow for function if import impure in initial inner input
loop model not operator or outer output package parameter partial protected public pure
record redeclare replaceable return stream then true type when while within
""".split())

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def is_identifier(name: str) -> bool:
    """True if *name* is a plain (non-quoted) Modelica identifier and not a keyword.

    >>> is_identifier("kht_in"), is_identifier("2x"), is_identifier("end")
    (True, False, False)
    """
    return isinstance(name, str) and bool(_IDENT.match(name)) and name not in MODELICA_KEYWORDS


def modelica_ident(name: str) -> str:
    """Return *name* if it is a valid Modelica identifier, else raise ``ValueError``.

    >>> modelica_ident("TI_102_meas")
    'TI_102_meas'
    """
    if not is_identifier(name):
        why = "is a Modelica keyword" if name in MODELICA_KEYWORDS else "is not a Modelica identifier"
        raise ValueError(f"{name!r} {why}")
    return name


def modelica_name(text: str) -> str:
    """Turn a tag or dotted name into an identifier: other characters become ``_``.

    A leading digit gets a ``_`` prefix; a keyword gets a ``_`` suffix.

    >>> modelica_name("TI-102"), modelica_name("hx.kht"), modelica_name("3 way")
    ('TI_102', 'hx_kht', '_3_way')
    """
    ident = re.sub(r"[^A-Za-z0-9_]", "_", str(text))
    if not ident:
        raise ValueError(f"cannot make a Modelica identifier from {text!r}")
    if ident[0].isdigit():
        ident = "_" + ident
    if ident in MODELICA_KEYWORDS:
        ident += "_"
    return ident


def tracked_output(parameter: str) -> str:
    """The tracked model's output carrying the tracked value of *parameter*.

    A component's parameter gives its dotted name as an identifier; a top-level parameter of
    the twin keeps its own name in the tracked model (it extends the twin), so its tracked
    value is ``<name>_tracked`` beside it.

    >>> tracked_output("hx.kht"), tracked_output("R1")
    ('hx_kht', 'R1_tracked')
    """
    ident = modelica_name(parameter)
    return ident if "." in parameter else f"{ident}_tracked"


def modelica_real(value: Any) -> str:
    """A finite number as a Modelica Real literal with ``repr`` precision.

    Integers get a decimal point so the literal is a Real; ``repr`` gives the
    shortest string that round-trips. NaN and infinities have no Modelica
    literal and raise ``ValueError``.

    >>> modelica_real(2), modelica_real(0.1), modelica_real(1e-5), modelica_real(-3e20)
    ('2.0', '0.1', '1e-05', '-3e+20')
    """
    if isinstance(value, bool):
        raise TypeError(f"expected a number, got a bool ({value!r}); use modelica_bool")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{value!r} has no Modelica literal (not finite)")
    if x == 0.0:
        return "0.0"  # no "-0.0" in generated code
    text = repr(x)
    if not any(c in text for c in ".eE"):
        text += ".0"
    return text


def modelica_bool(value: Any) -> str:
    """``true`` or ``false``; only real booleans are accepted.

    >>> modelica_bool(True)
    'true'
    """
    if not isinstance(value, bool):
        raise TypeError(f"expected a bool, got {type(value).__name__} ({value!r})")
    return "true" if value else "false"


def modelica_string(value: Any) -> str:
    r"""A double-quoted Modelica string literal.

    Backslash, double quote and control characters are escaped
    (``\\``, ``\"``, ``\n``, ``\t``, ``\r``).

    >>> print(modelica_string('say "hi"'))
    "say \"hi\""
    """
    text = str(value)
    out = text.replace("\\", "\\\\").replace('"', '\\"')
    out = out.replace("\n", "\\n").replace("\t", "\\t").replace("\r", "\\r")
    return f'"{out}"'


def modelica_literal(value: Any) -> str:
    """Any supported Python value as a Modelica literal (dispatches on type)."""
    if isinstance(value, bool):
        return modelica_bool(value)
    if isinstance(value, (int, float)):
        return modelica_real(value)
    if isinstance(value, str):
        return modelica_string(value)
    if isinstance(value, Sequence) or hasattr(value, "tolist"):
        return modelica_array(value)
    raise TypeError(f"no Modelica literal for {type(value).__name__} ({value!r})")


def modelica_array(values: Any) -> str:
    """A sequence as a Modelica array constructor, ``{1.0, 2.0}``.

    Elements are formatted by :func:`modelica_literal` (nested sequences give
    ``{{1.0, 2.0}, {3.0, 4.0}}``). An empty sequence gives ``fill(0.0, 0)``,
    since ``{}`` is not valid Modelica.

    >>> modelica_array([1, 2.5])
    '{1.0, 2.5}'
    """
    if hasattr(values, "tolist"):
        values = values.tolist()
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
        raise TypeError(f"expected a sequence, got {type(values).__name__}")
    if len(values) == 0:
        return "fill(0.0, 0)"
    return "{" + ", ".join(modelica_literal(v) for v in values) + "}"


def modelica_unit_modifier(unit: str, **attributes: Any) -> str:
    """A modifier ``(unit = "K", min = 0.0)`` from a unit (``""`` = none) and further attributes.

    Attributes whose value is ``None`` are left out; nothing at all gives ``""``.

    >>> modelica_unit_modifier("K"), modelica_unit_modifier("", min=0.0), modelica_unit_modifier("")
    ('(unit = "K")', '(min = 0.0)', '')
    """
    parts = [f"unit = {modelica_string(unit)}"] if unit else []
    parts += [f"{modelica_ident(k)} = {modelica_literal(v)}" for k, v in attributes.items() if v is not None]
    return "(" + ", ".join(parts) + ")" if parts else ""


def modelica_points(points: Any) -> str:
    """Graphics coordinates ``[(x, y), ...]`` as a Modelica array ``{{x, y}, ...}`` (integers where exact).

    >>> modelica_points([(-120, 15), (-40.5, 0)])
    '{{-120, 15}, {-40.5, 0}}'
    """
    def num(v: Any) -> str:
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"graphics coordinate must be finite, got {v!r}")
        return str(int(v)) if v == int(v) else repr(round(v, 3))

    pts = [(num(x), num(y)) for x, y in points]
    if not pts:
        raise ValueError("a line or extent needs at least one point")
    return "{" + ", ".join("{" + x + ", " + y + "}" for x, y in pts) + "}"


def unit_quotient(numerator: str, denominator: str) -> str:
    """The unit of a ratio, ``""`` when either unit is unknown.

    >>> unit_quotient("kg/s", "m"), unit_quotient("W", "m2.K"), unit_quotient("kg/s", "")
    ('(kg/s)/m', 'W/(m2.K)', '')
    """
    if not numerator or not denominator:
        return ""
    num = f"({numerator})" if "/" in numerator else numerator
    den = f"({denominator})" if any(c in denominator for c in "/.") else denominator
    return f"{num}/{den}"


def register(env: jinja2.Environment) -> jinja2.Environment:
    """Register the filters on *env* under short names (``real``, ``bool``, ...)."""
    env.filters.update({
        "real": modelica_real,
        "bool": modelica_bool,
        "array": modelica_array,
        "string": modelica_string,
        "ident": modelica_ident,
        "mname": modelica_name,
        "literal": modelica_literal,
        "unitmod": modelica_unit_modifier,
        "points": modelica_points,
    })
    return env
