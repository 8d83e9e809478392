"""Modelica array algebra on translated values (MLS chapter 10).

A translated value is a scalar (``int``, ``float``, ``bool`` or a CasADi
``MX``) or a NumPy object array of scalars whose shape is the Modelica array's
size. These functions give the operators and built-in array functions their
Modelica meaning:

* ``*`` is the matrix product for matrix*matrix, matrix*vector and
  vector*matrix, the scalar product for vector*vector, and element-wise only
  when one side is a scalar;
* ``A^n`` of a square matrix is the matrix power (``A^0`` the identity);
* ``+``/``-`` need equal sizes; the element-wise operators ``.+ .- .* ./ .^``
  broadcast a scalar;
* the constructors (``fill``, ``zeros``, ``ones``, ``identity``, ``diagonal``,
  ``linspace``, ``cat``, ``[a, b; c, d]``) and the reductions and conversions
  (``sum``, ``product``, ``min``, ``max``, ``size``, ``ndims``, ``scalar``,
  ``vector``, ``matrix``, ``transpose``, ``outerProduct``, ``symmetric``,
  ``cross``, ``skew``).

Sizes that do not fit and arguments a constant cannot take raise
:class:`ArrayError`; the translator adds the model, the expression and where it
stands.

>>> import numpy as np
>>> A = np.array([[1, 2], [3, 4]], dtype=object)
>>> matmul(A, A).tolist()
[[7, 10], [15, 22]]
>>> power(A, 0).tolist()
[[1.0, 0.0], [0.0, 1.0]]
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import casadi as ca
import numpy as np

from ..errors import CompileError

Value = Any  # int | float | bool | ca.MX | np.ndarray (object array of those)


class ArrayError(CompileError):
    """An array operation whose operands do not fit (size, kind or constant value)."""


def is_num(x: Value) -> bool:
    """True for a Python or NumPy number or Boolean (a folded constant)."""
    return isinstance(x, (int, float, bool, np.integer, np.floating, np.bool_))


def is_array(x: Value) -> bool:
    return isinstance(x, np.ndarray)


def shape(x: Value) -> tuple[int, ...]:
    """Modelica size of a value: ``()`` for a scalar."""
    return tuple(x.shape) if is_array(x) else ()


def size_text(s: tuple[int, ...]) -> str:
    return "scalar" if not s else "[" + ", ".join(str(d) for d in s) + "]"


def new(s: tuple[int, ...]) -> np.ndarray:
    return np.empty(s, dtype=object)


def from_list(values: Sequence[Value]) -> np.ndarray:
    out = new((len(values),))
    for i, v in enumerate(values):
        out[i] = v
    return out


def map1(fn: Callable[[Any], Any], a: Value) -> Value:
    """Apply a scalar function to every element."""
    if is_array(a):
        out = new(a.shape)
        for idx in np.ndindex(a.shape):
            out[idx] = fn(a[idx])
        return out
    return fn(a)


def map2(fn: Callable[[Any, Any], Any], a: Value, b: Value, what: str, broadcast: bool = True) -> Value:
    """Apply a binary scalar function element by element.

    Arrays must have equal sizes; a scalar is combined with every element of
    an array only when *broadcast* is true.
    """
    sa, sb = shape(a), shape(b)
    if sa and sb:
        if sa != sb:
            raise ArrayError(f"{what} of arrays of different sizes {size_text(sa)} and {size_text(sb)}")
    elif (sa or sb) and not broadcast:
        raise ArrayError(f"{what} of a scalar and an array of size {size_text(sa or sb)} "
                         f"(Modelica needs the element-wise operator here)")
    if not sa and not sb:
        return fn(a, b)
    s = sa or sb
    out = new(s)
    for idx in np.ndindex(s):
        out[idx] = fn(a[idx] if sa else a, b[idx] if sb else b)
    return out


def _dot(xs: Sequence[Value], ys: Sequence[Value]) -> Value:
    acc: Value = 0.0
    first = True
    for x, y in zip(xs, ys):
        term = x * y
        acc = term if first else acc + term
        first = False
    return acc


def matmul(a: Value, b: Value) -> Value:
    """Modelica ``a * b`` (MLS 10.6.4)."""
    sa, sb = shape(a), shape(b)
    if not sa or not sb:
        return map2(lambda x, y: x * y, a, b, "multiplication")
    if len(sa) == 1 and len(sb) == 1:
        if sa != sb:
            raise ArrayError(f"scalar product of vectors of sizes {size_text(sa)} and {size_text(sb)}")
        return _dot(list(a), list(b))
    if len(sa) == 1 and len(sb) == 2:
        if sa[0] != sb[0]:
            raise ArrayError(f"vector*matrix product of sizes {size_text(sa)} and {size_text(sb)}")
        return from_list([_dot(list(a), list(b[:, j])) for j in range(sb[1])])
    if len(sa) == 2 and len(sb) == 1:
        if sa[1] != sb[0]:
            raise ArrayError(f"matrix*vector product of sizes {size_text(sa)} and {size_text(sb)}")
        return from_list([_dot(list(a[i, :]), list(b)) for i in range(sa[0])])
    if len(sa) == 2 and len(sb) == 2:
        if sa[1] != sb[0]:
            raise ArrayError(f"matrix product of sizes {size_text(sa)} and {size_text(sb)}")
        out = new((sa[0], sb[1]))
        for i in range(sa[0]):
            for j in range(sb[1]):
                out[i, j] = _dot(list(a[i, :]), list(b[:, j]))
        return out
    raise ArrayError(f"product '*' of arrays of sizes {size_text(sa)} and {size_text(sb)} "
                     "(only vectors and matrices multiply; use .* for element-wise)")


def divide(a: Value, b: Value) -> Value:
    """Modelica ``a / b``: the divisor must be a scalar."""
    if is_array(b):
        raise ArrayError(f"division '/' by an array of size {size_text(shape(b))} (use ./ for element-wise)")
    return map1(lambda x: scalar_div(x, b), a)


def scalar_div(x: Value, y: Value) -> Value:
    if is_num(x) and is_num(y):
        if float(y) == 0.0:
            raise ArrayError(f"division by zero: {x} / {y}")
        return float(x) / float(y)
    return x / y


def scalar_pow(x: Value, y: Value) -> Value:
    """Scalar ``x ^ y`` (folded when both are constants)."""
    if is_num(x) and is_num(y):
        fx, fy = float(x), float(y)
        if fx == 0.0 and fy < 0:
            raise ArrayError(f"{x} ^ {y}: zero to a negative power")
        if fx < 0 and not fy.is_integer():
            raise ArrayError(f"{x} ^ {y}: negative base with a non-integer exponent")
        try:
            return fx ** fy
        except OverflowError:
            raise ArrayError(f"{x} ^ {y} overflows") from None
    if is_num(y) and float(y) == 2.0:
        return x * x
    if is_num(y) and float(y).is_integer() and 0 < abs(float(y)) <= 8:
        return ca.constpow(x, float(y))
    return ca.power(x, y)


def identity(n: int) -> np.ndarray:
    out = new((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = 1.0 if i == j else 0.0
    return out


def power(a: Value, n: Value) -> Value:
    """Modelica ``a ^ n``: scalar power, or the power of a square matrix by a constant Integer >= 0."""
    sa = shape(a)
    if is_array(n):
        raise ArrayError(f"exponent '^' of size {size_text(shape(n))} (use .^ for element-wise)")
    if not sa:
        return scalar_pow(a, n)
    if len(sa) != 2 or sa[0] != sa[1]:
        raise ArrayError(f"power '^' of an array of size {size_text(sa)}: only a square matrix has one "
                         "(use .^ for element-wise)")
    if not is_num(n) or isinstance(n, (bool, np.bool_)) or float(n) < 0 or not float(n).is_integer():
        raise ArrayError(f"matrix power A^{n}: the exponent must be a constant Integer >= 0")
    result: Value = identity(sa[0])
    for _ in range(int(n)):
        result = matmul(result, a)
    return result


def stack(values: Sequence[Value], what: str = "array constructor {...}") -> np.ndarray:
    """``{a, b, ...}``: a new first dimension over elements of equal size."""
    if not values:
        return new((0,))
    s = shape(values[0])
    for v in values[1:]:
        if shape(v) != s:
            raise ArrayError(f"{what} with elements of different sizes {size_text(s)} and {size_text(shape(v))}")
    out = new((len(values),) + s)
    for i, v in enumerate(values):
        out[i] = v
    return out


def ints(args: Sequence[Value], what: str) -> list[int]:
    out = []
    for a in args:
        if not is_num(a) or isinstance(a, (bool, np.bool_)) or not float(a).is_integer():
            raise ArrayError(f"{what} needs constant Integer sizes, got {a!r}")
        if int(a) < 0:
            raise ArrayError(f"{what} with a negative size {int(a)}")
        out.append(int(a))
    return out


def fill(value: Value, dims: Sequence[Value], what: str = "fill()") -> np.ndarray:
    ns = tuple(ints(dims, what))
    if not ns:
        raise ArrayError(f"{what} needs at least one size")
    out = new(ns + shape(value))
    for idx in np.ndindex(ns):
        out[idx] = value
    return out


def cat(k: Value, arrays: Sequence[Value], what: str = "cat()") -> np.ndarray:
    """``cat(k, A, B, ...)``: concatenation along dimension *k* (1-based)."""
    (kk,) = ints([k], what)
    if not arrays:
        raise ArrayError(f"{what} without arrays")
    shapes = [shape(a) for a in arrays]
    nd = len(shapes[0])
    if nd == 0 or any(len(s) != nd for s in shapes):
        raise ArrayError(f"{what} of arrays with different numbers of dimensions: "
                         + ", ".join(size_text(s) for s in shapes))
    if not 1 <= kk <= nd:
        raise ArrayError(f"{what} along dimension {kk} of arrays with {nd} dimension(s)")
    for s in shapes[1:]:
        if s[:kk - 1] + s[kk:] != shapes[0][:kk - 1] + shapes[0][kk:]:
            raise ArrayError(f"{what} along dimension {kk} of arrays of sizes "
                             + ", ".join(size_text(s) for s in shapes))
    return np.concatenate([np.asarray(a, dtype=object) for a in arrays], axis=kk - 1)


def promote2(a: Value) -> np.ndarray:
    """Append dimensions of size one up to a matrix (MLS ``promote(A, 2)``)."""
    s = shape(a)
    if len(s) > 2:
        return np.asarray(a, dtype=object)
    out = new(s + (1,) * (2 - len(s)))
    if not s:
        out[0, 0] = a
    elif len(s) == 1:
        for i in range(s[0]):
            out[i, 0] = a[i]
    else:
        out[...] = a
    return out


def sizes(a: Value, dim: Value | None = None) -> Value:
    """``size(A)`` (vector of sizes) or ``size(A, i)``."""
    s = shape(a)
    if dim is None:
        return from_list(list(s))
    (i,) = ints([dim], "size(A, i)")
    if not 1 <= i <= len(s):
        raise ArrayError(f"size(A, {i}) of an array of size {size_text(s)}")
    return s[i - 1]


def transpose(a: Value) -> np.ndarray:
    s = shape(a)
    if len(s) < 2:
        raise ArrayError(f"transpose() of a value of size {size_text(s)}: it needs a matrix")
    return np.swapaxes(a, 0, 1).copy()


def outer(x: Value, y: Value) -> np.ndarray:
    if len(shape(x)) != 1 or len(shape(y)) != 1:
        raise ArrayError(f"outerProduct() of sizes {size_text(shape(x))} and {size_text(shape(y))}: it needs vectors")
    out = new((len(x), len(y)))
    for i in range(len(x)):
        for j in range(len(y)):
            out[i, j] = x[i] * y[j]
    return out


def diagonal(v: Value) -> np.ndarray:
    if len(shape(v)) != 1:
        raise ArrayError(f"diagonal() of a value of size {size_text(shape(v))}: it needs a vector")
    n = len(v)
    out = new((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = v[i] if i == j else 0.0
    return out


def linspace(x1: Value, x2: Value, n: Value) -> np.ndarray:
    (nn,) = ints([n], "linspace()")
    if nn < 2:
        raise ArrayError(f"linspace() with n = {nn}: n must be at least 2")
    return from_list([x1 + (x2 - x1) * (i / (nn - 1)) for i in range(nn)])


def symmetric(a: Value) -> np.ndarray:
    s = shape(a)
    if len(s) != 2 or s[0] != s[1]:
        raise ArrayError(f"symmetric() of a value of size {size_text(s)}: it needs a square matrix")
    out = new(s)
    for i in range(s[0]):
        for j in range(s[1]):
            out[i, j] = a[i, j] if i <= j else a[j, i]
    return out


def _vector3(x: Value, what: str) -> None:
    if shape(x) != (3,):
        raise ArrayError(f"{what} of a value of size {size_text(shape(x))}: it needs a vector of size 3")


def cross(x: Value, y: Value) -> np.ndarray:
    _vector3(x, "cross()")
    _vector3(y, "cross()")
    return from_list([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])


def skew(x: Value) -> np.ndarray:
    _vector3(x, "skew()")
    out = new((3, 3))
    rows = [[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]]
    for i in range(3):
        for j in range(3):
            out[i, j] = rows[i][j]
    return out


def to_scalar(a: Value) -> Value:
    s = shape(a)
    if any(d != 1 for d in s):
        raise ArrayError(f"scalar() of an array of size {size_text(s)}: every size must be 1")
    return a[(0,) * len(s)] if s else a


def to_vector(a: Value) -> Value:
    s = shape(a)
    if sum(1 for d in s if d > 1) > 1:
        raise ArrayError(f"vector() of an array of size {size_text(s)}: at most one size may exceed 1")
    if not s:
        return from_list([a])
    return from_list(list(np.asarray(a, dtype=object).ravel()))


def to_matrix(a: Value) -> np.ndarray:
    s = shape(a)
    if any(d != 1 for d in s[2:]):
        raise ArrayError(f"matrix() of an array of size {size_text(s)}: sizes beyond the second must be 1")
    p = promote2(a)
    return p.reshape(p.shape[:2])


def elements(values: Sequence[Value]) -> list[Value]:
    """Every scalar of the values, arrays flattened in row-major order."""
    out: list[Value] = []
    for v in values:
        if is_array(v):
            out.extend(v.ravel().tolist())
        else:
            out.append(v)
    return out


def reduce_sum(a: Value) -> Value:
    vals = elements([a])
    if not vals:
        return 0.0
    acc = vals[0]
    for v in vals[1:]:
        acc = acc + v
    return acc


def reduce_product(a: Value) -> Value:
    vals = elements([a])
    if not vals:
        return 1.0
    acc = vals[0]
    for v in vals[1:]:
        acc = acc * v
    return acc


def extremum(values: list[Value], which: str) -> Value:
    """min/max of scalars; a constant pair is folded, anything else uses fmin/fmax."""
    if not values:
        raise ArrayError(f"{which}() of an empty array")
    acc = values[0]
    for v in values[1:]:
        if is_num(acc) and is_num(v):
            acc = min(acc, v) if which == "min" else max(acc, v)
        else:
            acc = ca.fmin(acc, v) if which == "min" else ca.fmax(acc, v)
    return acc


def subscript(a: Value, subs: Sequence[Value | None], what: str) -> Value:
    """Index *a* with 1-based subscripts: an Integer, a vector of Integers, ``None`` for ``:``, or a
    scalar expression (an Integer variable, see :func:`_select`)."""
    s = shape(a)
    if len(subs) > len(s):
        raise ArrayError(f"{len(subs)} subscripts for {what} of size {size_text(s)}")
    for k, sub in enumerate(subs):
        if isinstance(sub, (ca.MX, ca.SX)):
            picked = subscript(a, [None] * k + [1] + [None] * (len(s) - k - 1), what)
            options = [subscript(a, [None] * k + [i] + [None] * (len(s) - k - 1), what) for i in range(1, s[k] + 1)]
            rest = list(subs[:k]) + list(subs[k + 1:])
            chosen = _select(sub, options, picked)
            return subscript(chosen, rest, what) if any(r is not None for r in rest) else chosen
    index: list[Any] = []
    for k, sub in enumerate(subs):
        n = s[k]
        if sub is None:
            index.append(slice(None))
            continue
        if is_array(sub):
            if len(sub.shape) != 1:
                raise ArrayError(f"subscript of size {size_text(sub.shape)} for {what}")
            ks = ints(list(sub), f"subscript of {what}")
            for i in ks:
                if not 1 <= i <= n:
                    raise ArrayError(f"index {i} out of range 1..{n} for dimension {k + 1} of {what}")
            index.append([i - 1 for i in ks])
            continue
        (i,) = ints([sub], f"subscript of {what}")
        if not 1 <= i <= n:
            raise ArrayError(f"index {i} out of range 1..{n} for dimension {k + 1} of {what}")
        index.append(i - 1)
    # apply one dimension at a time so that vector subscripts do not combine NumPy-style
    result = np.asarray(a, dtype=object)
    axis = 0
    for idx in index:
        if isinstance(idx, int):
            result = np.take(result, idx, axis=axis)
        elif isinstance(idx, list):
            result = np.take(result, idx, axis=axis)
            axis += 1
        else:
            axis += 1
    if isinstance(result, np.ndarray) and result.shape == ():
        return result[()]
    return result


def _select(index: Any, options: list[Value], like: Value) -> Value:
    """``options[index - 1]`` for a scalar *index* known only when the model runs, element by element
    (each option has the size of *like*): ``if index == 1 then options[1] elseif ... else NaN``. An
    index outside ``1..n`` is an error in Modelica (MLS 10.5); here it gives NaN, which the run
    shows instead of a number taken from a wrong element."""
    def pick(*elements: Any) -> Any:
        out: Any = ca.MX(float("nan")) if isinstance(index, ca.MX) else ca.SX(float("nan"))
        for i in range(len(elements), 0, -1):
            out = ca.if_else(index == i, elements[i - 1], out)
        return out
    if not is_array(like):
        return pick(*options)
    out = new(like.shape)
    for pos in np.ndindex(*like.shape):
        out[pos] = pick(*(o[pos] for o in options))
    return out


def fold_math(name: str, fn: Callable[[float], float], x: Value) -> float:
    """Fold a mathematical function of a constant; invalid arguments are an :class:`ArrayError`."""
    try:
        y = fn(float(x))
    except (ValueError, ZeroDivisionError):
        raise ArrayError(f"{name}({x:g}) is undefined (argument outside the function's domain)") from None
    except OverflowError:
        raise ArrayError(f"{name}({x:g}) overflows") from None
    if isinstance(y, complex) or (isinstance(y, float) and math.isnan(y)):
        raise ArrayError(f"{name}({x:g}) is undefined")
    return y
