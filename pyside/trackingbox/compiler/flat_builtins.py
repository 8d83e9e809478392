"""Modelica's operators and built-in functions on translated values (floats, booleans, CasADi ``MX``
and object arrays of them), for :class:`.flatten.FlatTranslator`: constant operands fold to
constants, the rest becomes CasADi expressions; the built-ins recognised by name and the
constructs refused.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from . import arrays as arr
from .arrays import ArrayError
from .flat_model import Value

if TYPE_CHECKING:
    from .flatten import FlatTranslator


UNSUPPORTED_BUILTINS = {
    "reinit": r"\breinit\s*\(",
    "delay": r"\bdelay\s*\(",
    "spatialdistribution": r"\bspatialDistribution\s*\(",
    "cardinality": r"\bcardinality\s*\(",
    "assert": r"\bassert\s*\(",
    "terminate": r"\bterminate\s*\(",
    "hold": r"\bhold\s*\(",
    "previous": r"\bprevious\s*\(",
    "subsample": r"\bsubSample\s*\(",
    "supersample": r"\bsuperSample\s*\(",
    "shiftsample": r"\bshiftSample\s*\(",
    "backsample": r"\bbackSample\s*\(",
    "noclock": r"\bnoClock\s*\(",
    "interval": r"\binterval\s*\(",
    "clock": r"\bClock\s*\(",
}


EVENT_BUILTINS = {"pre", "edge", "change", "initial", "terminal", "sample"}


def is_number(x: Value) -> bool:
    return isinstance(x, (int, float, bool, np.integer, np.floating, np.bool_))


def plain_ge(a: Value, b: Value) -> Value:
    """``a >= b`` evaluated as it stands (no event)."""
    if is_number(a) and is_number(b):
        return a >= b
    return (ca.MX(a) if is_number(a) else a) >= b


def if_then(cond: Value, a: Value, b: Value) -> Value:
    """``if cond then a else b`` for scalars (a constant condition picks a branch)."""
    if is_number(cond):
        return a if bool(cond) else b
    if a is b:
        return a
    return ca.if_else(cond, a, b)


def solve_scalar_linear(res: ca.MX, v: ca.MX) -> ca.MX | None:
    jac = ca.jacobian(res, v)
    if ca.depends_on(jac, v):
        return None
    if jac.is_zero():
        return None
    r0 = ca.substitute(res, v, ca.MX(0))
    return -r0 / jac


BUILTIN_NAMES = {
    "abs", "sqrt", "exp", "log", "log10", "sin", "cos", "tan", "asin", "acos", "atan", "atan2",
    "sinh", "cosh", "tanh", "min", "max", "sign", "floor", "ceil", "noEvent", "smooth", "homotopy",
    "semiLinear", "sum", "product", "integer", "div", "mod", "rem",
}

# array built-ins (MLS 10.3): recognised by name when the model defines no function of that name
ARRAY_BUILTINS = {
    "size", "ndims", "scalar", "vector", "matrix", "identity", "diagonal", "zeros", "ones", "fill",
    "linspace", "cat", "transpose", "outerproduct", "symmetric", "cross", "skew",
}


_BUILTIN_EXTERNALS = {
    "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "exp", "log", "log10",
    "sqrt", "abs", "sign", "floor", "ceil",
}
"""Functions an ``external "builtin"`` declaration may name (MLS 12.9: the built-ins of the language,
as Modelica.Math declares its elementary functions)."""


def builtin_external_name(ext: Any) -> str | None:
    """The built-in an ``external "builtin"`` clause calls, or None (another language, or unknown)."""
    if not isinstance(ext, dict) or str(ext.get("language", "")).lower() != "builtin":
        return None
    name = str(ext.get("function_name") or "")
    return name if name in _BUILTIN_EXTERNALS else None


def logical_not(a: Any) -> Any:
    return (not a) if is_number(a) else ca.logic_not(a)


def binary(op: str, a: Value, b: Value, tr: FlatTranslator) -> Value:
    """A binary operator with its Modelica meaning (rumoca names: Add, Sub, Mul, Div, Exp, and
    AddElem ... ExpElem for the element-wise ``.+ .- .* ./ .^``)."""
    o = op.lower()
    elementwise = False
    for prefix in ("dot", "elem"):
        if o.startswith(prefix):
            o, elementwise = o[len(prefix):], True
    if o.endswith("elem"):
        o, elementwise = o[: -len("elem")], True
    if o in ("add", "plus"):
        return arr.map2(lambda x, y: x + y, a, b, "'.+'" if elementwise else "addition '+'", broadcast=elementwise)
    if o in ("sub", "minus"):
        return arr.map2(lambda x, y: x - y, a, b, "'.-'" if elementwise else "subtraction '-'",
                        broadcast=elementwise)
    if o in ("mul", "times"):
        if elementwise:
            return arr.map2(lambda x, y: x * y, a, b, "'.*'")
        return arr.matmul(a, b)
    if o == "div":
        if elementwise:
            return arr.map2(arr.scalar_div, a, b, "'./'")
        return arr.divide(a, b)
    if o in ("exp", "pow", "power"):
        if elementwise:
            return arr.map2(arr.scalar_pow, a, b, "'.^'")
        return arr.power(a, b)
    cmp = {"lt": "<", "le": "<=", "gt": ">", "ge": ">=", "eq": "==", "neq": "!=", "ne": "!="}
    if o in cmp:
        if arr.is_array(a) or arr.is_array(b):
            raise ArrayError(f"relational operator {cmp[o]} on arrays (sizes {arr.size_text(arr.shape(a))} "
                             f"and {arr.size_text(arr.shape(b))}); Modelica compares scalars only")
        return tr.relation(cmp[o], a, b)
    if o in ("and", "or"):
        return arr.map2(logical_and if o == "and" else logical_or, a, b, f"'{o}'", broadcast=False)
    raise tr.unsupported(f"binary operator {op!r}")


def logical_and(a: Any, b: Any) -> Any:
    if (is_number(a) and not a) or (is_number(b) and not b):
        return False
    if is_number(a):
        return b
    if is_number(b):
        return a
    return ca.logic_and(a, b)


def logical_or(a: Any, b: Any) -> Any:
    if (is_number(a) and a) or (is_number(b) and b):
        return True
    if is_number(a):
        return b
    if is_number(b):
        return a
    return ca.logic_or(a, b)


_SIMPLE = {
    "sqrt": (math.sqrt, ca.sqrt), "exp": (math.exp, ca.exp), "log": (math.log, ca.log),
    "log10": (math.log10, ca.log10), "sin": (math.sin, ca.sin), "cos": (math.cos, ca.cos),
    "tan": (math.tan, ca.tan), "asin": (math.asin, ca.asin), "acos": (math.acos, ca.acos),
    "atan": (math.atan, ca.atan), "sinh": (math.sinh, ca.sinh), "cosh": (math.cosh, ca.cosh),
    "tanh": (math.tanh, ca.tanh), "abs": (abs, ca.fabs), "floor": (math.floor, ca.floor),
    "ceil": (math.ceil, ca.ceil), "sign": (lambda x: float(np.sign(x)), ca.sign),
    "integer": (lambda x: float(math.floor(x)), ca.floor),
}


def _arity(name: str, args: list[Value], *allowed: int) -> None:
    if len(args) not in allowed:
        want = " or ".join(str(n) for n in allowed)
        raise ArrayError(f"{name}() takes {want} argument(s), got {len(args)}")


def builtin_call(name: str, args: list[Value], tr: FlatTranslator) -> Value:
    n = name.lower()
    if n in ("floor", "ceil", "integer"):
        _arity(n, args, 1)
        f_num = _SIMPLE[n][0]
        return arr.map1(lambda a: arr.fold_math(n, f_num, a) if is_number(a) else tr.rounding(n, a), args[0])
    if n in _SIMPLE:
        _arity(n, args, 1)
        f_num, f_sym = _SIMPLE[n]
        return arr.map1(lambda a: arr.fold_math(n, f_num, a) if is_number(a) else f_sym(a), args[0])
    if n == "noevent":
        return args[0]
    if n == "smooth":
        return args[1]
    if n == "homotopy":
        return args[0]
    if n == "semilinear":
        x, a, b = args
        return ca.if_else(x >= 0, a * x, b * x) if not is_number(x) else (a * x if x >= 0 else b * x)
    if n == "atan2":
        _arity(n, args, 2)
        return arr.map2(lambda y, x: math.atan2(y, x) if is_number(y) and is_number(x) else ca.atan2(y, x),
                        args[0], args[1], "atan2()")
    if n in ("min", "max"):
        _arity(n, args, 1, 2)
        if len(args) == 1:  # reduction over an array (or a comprehension)
            if not arr.is_array(args[0]):
                raise ArrayError(f"{n}() of one scalar: it needs an array or two scalars")
            return arr.extremum(arr.elements(args), n)
        if arr.is_array(args[0]) or arr.is_array(args[1]):
            raise ArrayError(f"{n}(a, b) of sizes {arr.size_text(arr.shape(args[0]))} and "
                             f"{arr.size_text(arr.shape(args[1]))}: it takes two scalars or one array")
        return arr.extremum(list(args), n)
    if n == "sum":
        _arity(n, args, 1)
        return arr.reduce_sum(args[0])
    if n == "product":
        _arity(n, args, 1)
        return arr.reduce_product(args[0])
    if n in ("div", "mod", "rem"):
        _arity(n, args, 2)
        return arr.map2(lambda a, b: _divmod(n, a, b, tr), args[0], args[1], f"{n}()", broadcast=False)
    if n == "size":
        _arity(n, args, 1, 2)
        return arr.sizes(args[0], args[1] if len(args) == 2 else None)
    if n == "ndims":
        _arity(n, args, 1)
        return len(arr.shape(args[0]))
    if n == "scalar":
        _arity(n, args, 1)
        return arr.to_scalar(args[0])
    if n == "vector":
        _arity(n, args, 1)
        return arr.to_vector(args[0])
    if n == "matrix":
        _arity(n, args, 1)
        return arr.to_matrix(args[0])
    if n == "identity":
        _arity(n, args, 1)
        (size,) = arr.ints(args, "identity()")
        return arr.identity(size)
    if n == "diagonal":
        _arity(n, args, 1)
        return arr.diagonal(args[0])
    if n in ("zeros", "ones"):
        return arr.fill(0.0 if n == "zeros" else 1.0, args, f"{n}()")
    if n == "fill":
        if len(args) < 2:
            raise ArrayError("fill() needs a value and at least one size")
        return arr.fill(args[0], args[1:])
    if n == "linspace":
        _arity(n, args, 3)
        return arr.linspace(*args)
    if n == "cat":
        if len(args) < 2:
            raise ArrayError("cat() needs a dimension and at least one array")
        return arr.cat(args[0], args[1:])
    if n == "transpose":
        _arity(n, args, 1)
        return arr.transpose(args[0])
    if n == "outerproduct":
        _arity(n, args, 2)
        return arr.outer(args[0], args[1])
    if n == "symmetric":
        _arity(n, args, 1)
        return arr.symmetric(args[0])
    if n == "cross":
        _arity(n, args, 2)
        return arr.cross(args[0], args[1])
    if n == "skew":
        _arity(n, args, 1)
        return arr.skew(args[0])
    raise tr.unsupported(f"built-in {n}()", rf"\b{n}\s*\(")


def _divmod(n: str, a: Value, b: Value, tr: FlatTranslator) -> Value:
    if is_number(a) and is_number(b):
        if float(b) == 0.0:
            raise ArrayError(f"{n}({a}, {b}): division by zero")
        if n == "div":
            return float(math.trunc(a / b))
        if n == "mod":
            return a - math.floor(a / b) * b
        return a - math.trunc(a / b) * b
    if n == "mod":
        return a - ca.floor(a / b) * b
    q = a / b
    truncated = ca.sign(q) * ca.floor(ca.fabs(q))  # integer part, towards zero
    if n == "div":
        return truncated
    return a - truncated * b
