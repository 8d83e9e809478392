"""LAPACK routines called by ``external "FORTRAN 77"`` functions, given their meaning on the
embedded path (the Modelica Standard Library's ``Modelica.Math.Matrices.LAPACK`` wrappers, which
``Matrices.solve``, ``solve2``, ``leastSquares``, ``leastSquares2`` and ``Polynomials.fitting``
call, and any other function that calls the same routines).

A routine gets the values of the external call's arguments in their order (MLS 12.9: a Modelica
array ``A[i, j]`` is the Fortran ``A(i, j)``) and returns, by argument position, the values it
writes. Where every argument it reads is a constant at translation, the routine is LAPACK's own,
through SciPy's bindings (``scipy.linalg.lapack``): the same factorisation, pivots, rank decision
and ``info`` a compiled call gives. Where the matrix depends on parameters or variables:

* ``dgesv`` (solve ``A*X = B`` by LU with partial pivoting) is CasADi's linear solve of the same
  system (exact, and differentiable); ``info`` is nonzero exactly where ``det(A)`` is zero, the
  singularity LAPACK reports, and the factors and pivots (which no MSL wrapper returns) are not
  produced: a function returning them is refused;
* ``dgelsy`` (rank-revealing least squares) is refused: its result depends on a rank decision
  that a symbolic expression cannot take.

Any other routine is refused by the translator, naming the function and where it is declared.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np
from scipy.linalg import lapack as _lapack

from .arrays import is_num


class NotGiven(Exception):
    """The routine cannot give its meaning to these arguments (the message says why)."""


def _matrix(value: Any, rows: int, cols: int, what: str) -> np.ndarray:
    """*value* (a matrix, or a vector for one column) as an object array of *rows* x *cols*."""
    a = np.asarray(value, dtype=object)
    if a.ndim == 1 and cols == 1:
        a = a.reshape(-1, 1)
    if a.ndim != 2 or a.shape[0] < rows or a.shape[1] < cols:
        raise NotGiven(f"{what} has size {a.shape}, not at least {rows} x {cols}")
    return a[:rows, :cols]


def _is_constant(*arrays: np.ndarray) -> bool:
    return all(is_num(x) for a in arrays for x in a.ravel())


def _int(value: Any, what: str) -> int:
    if not is_num(value):
        raise NotGiven(f"{what} is not a constant")
    return int(value)


def _like(result: np.ndarray, original: Any) -> np.ndarray:
    """*result* (rows x cols) in the shape of *original*, with the rows *original* has beyond it kept."""
    orig = np.asarray(original, dtype=object)
    out = orig.reshape(orig.shape[0], -1).copy()
    out[: result.shape[0], : result.shape[1]] = result
    return out.reshape(orig.shape)


def _to_mx(a: np.ndarray) -> ca.MX:
    return ca.vertcat(*[ca.horzcat(*[ca.MX(x) if is_num(x) else x for x in row]) for row in a])


def _from_mx(m: ca.MX, rows: int, cols: int) -> np.ndarray:
    out = np.empty((rows, cols), dtype=object)
    for i in range(rows):
        for j in range(cols):
            out[i, j] = m[i, j]
    return out


def dgesv(args: list[Any]) -> dict[int, Any]:
    """``dgesv(n, nrhs, A, lda, ipiv, B, ldb, info)``: B := the solution X of A*X = B."""
    if len(args) != 8:
        raise NotGiven(f"dgesv takes 8 arguments, the call gives {len(args)}")
    n, nrhs = _int(args[0], "n"), _int(args[1], "nrhs")
    a = _matrix(args[2], n, n, "A")
    b = _matrix(args[5], n, nrhs, "B")
    if _is_constant(a, b):
        lu, piv, x, info = _lapack.dgesv(np.array(a, dtype=float), np.array(b, dtype=float))
        return {2: _like(np.array(lu, dtype=object), args[2]), 4: np.array([int(p) + 1 for p in piv], dtype=object),
                5: _like(np.array(x, dtype=object), args[5]), 7: int(info)}
    ma, mb = _to_mx(a), _to_mx(b)
    info = ca.if_else(ca.det(ma) == 0, 1, 0) if n > 0 else 0
    return {5: _like(_from_mx(ca.solve(ma, mb), n, nrhs), args[5]), 7: info}


def dgelsy(args: list[Any]) -> dict[int, Any]:
    """``dgelsy(m, n, nrhs, A, lda, B, ldb, jpvt, rcond, rank, work, lwork, info)``: the minimum-norm
    least-squares solution of A*X = B, with the rank decided by *rcond*."""
    if len(args) != 13:
        raise NotGiven(f"dgelsy takes 13 arguments, the call gives {len(args)}")
    m, n, nrhs = _int(args[0], "m"), _int(args[1], "n"), _int(args[2], "nrhs")
    a = _matrix(args[3], m, n, "A")
    b = _matrix(args[5], max(m, n), nrhs, "B")
    jpvt = np.asarray(args[7], dtype=object).ravel()
    if not _is_constant(a, b, jpvt) or not is_num(args[8]):
        raise NotGiven("its matrix, right-hand side or rcond depends on parameters or variables "
                       "(the rank decision of a least-squares solve needs their values)")
    lwork = max(1, _int(args[11], "lwork"), min(m, n) + 3 * n + 1, 2 * min(m, n) + nrhs)  # the call's own size
    v, x, j, rank, info = _lapack.dgelsy(np.array(a, dtype=float), np.array(b, dtype=float),
                                         np.array(jpvt, dtype=np.int32), float(args[8]), lwork)
    return {3: _like(np.array(v, dtype=object), args[3]), 5: _like(np.array(x, dtype=object), args[5]),
            7: np.array([int(k) for k in j], dtype=object), 9: int(rank), 12: int(info)}


ROUTINES: dict[str, Callable[[list[Any]], dict[int, Any]]] = {"dgesv": dgesv, "dgelsy": dgelsy}
"""LAPACK routine name (lower case) -> its meaning on the arguments' values."""
