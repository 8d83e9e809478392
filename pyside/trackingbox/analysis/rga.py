"""Relative gain array, condition number and gain scaling.

Plain functions on a steady-state gain matrix ``G`` (rows: tracking variables,
columns: candidate parameters), ``g_ij = dy_i / dp_j``.
"""
from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import AnalysisError

logger = logging.getLogger(__name__)

#: Default relative tolerance on singular values: ``s_k < rtol * s_max`` counts as zero.
DEFAULT_RTOL = 1e-8


@dataclass(frozen=True)
class RankReport:
    """Rank of a gain matrix and which columns/rows depend on the others.

    Attributes
    ----------
    rank : int
        Numerical rank.
    shape : tuple of int
        ``(variables, parameters)``.
    dependent_columns : tuple of int
        Columns that are (numerically) linear combinations of earlier kept columns,
        scanned strongest first.
    dependent_rows : tuple of int
        Rows that are linear combinations of kept rows, scanned the same way.
    """

    rank: int
    shape: tuple[int, int]
    dependent_columns: tuple[int, ...]
    dependent_rows: tuple[int, ...]

    @property
    def full(self) -> bool:
        """True when ``rank == min(shape)`` (the RGA is well defined)."""
        return self.rank == min(self.shape)


def _as_matrix(G: npt.ArrayLike) -> np.ndarray:
    A = np.asarray(G, dtype=float)
    if A.ndim == 1:
        A = A.reshape(1, -1)
    if A.ndim != 2 or A.size == 0:
        raise AnalysisError(f"gain matrix must be a non-empty 2-D array, got shape {np.shape(G)}")
    if not np.all(np.isfinite(A)):
        bad = [tuple(int(k) for k in idx) for idx in np.argwhere(~np.isfinite(A))[:5]]
        raise AnalysisError(f"gain matrix has non-finite entries at (row, column) {bad}")
    return A


def _rank(A: np.ndarray, rtol: float) -> int:
    s = np.linalg.svd(A, compute_uv=False)
    if s.size == 0 or s[0] == 0.0:
        return 0
    return int(np.sum(s > rtol * s[0]))


def _greedy_independent(A: np.ndarray, rtol: float, scale: float) -> tuple[list[int], list[int]]:
    """Scan columns of *A* strongest first; keep those that raise the rank."""
    order = np.argsort(-np.linalg.norm(A, axis=0), kind="stable")
    kept: list[int] = []
    dependent: list[int] = []
    for j in order:
        if len(kept) >= A.shape[0]:
            dependent.append(int(j))
            continue
        trial = A[:, kept + [int(j)]]
        s = np.linalg.svd(trial, compute_uv=False)
        if scale > 0 and s[-1] > rtol * scale:
            kept.append(int(j))
        else:
            dependent.append(int(j))
    return sorted(kept), sorted(dependent)


def rank_report(G: npt.ArrayLike, *, rtol: float = DEFAULT_RTOL) -> RankReport:
    """Numerical rank of *G* and its dependent columns and rows.

    Parameters
    ----------
    G : array_like, shape (m, n)
        Gain matrix.
    rtol : float
        Singular values below ``rtol * s_max`` count as zero.

    Returns
    -------
    RankReport

    Examples
    --------
    >>> rank_report([[1.0, 2.0], [2.0, 4.0]]).dependent_columns
    (0,)
    """
    A = _as_matrix(G)
    s = np.linalg.svd(A, compute_uv=False)
    scale = float(s[0]) if s.size else 0.0
    rank = _rank(A, rtol)
    _, dep_cols = _greedy_independent(A, rtol, scale)
    _, dep_rows = _greedy_independent(A.T, rtol, scale)
    return RankReport(rank=rank, shape=(A.shape[0], A.shape[1]),
                      dependent_columns=tuple(dep_cols), dependent_rows=tuple(dep_rows))


def _names(names: Sequence[str] | None, n: int, prefix: str) -> list[str]:
    if names is None:
        return [f"{prefix} {k}" for k in range(n)]
    if len(names) != n:
        raise AnalysisError(f"{len(names)} {prefix} names given for {n} {prefix}s")
    return [str(x) for x in names]


def check_rank(G: npt.ArrayLike, *, variables: Sequence[str] | None = None,
               parameters: Sequence[str] | None = None, rtol: float = DEFAULT_RTOL) -> RankReport:
    """Raise :class:`AnalysisError` naming the dependent columns/rows if *G* is rank deficient.

    Parameters
    ----------
    G : array_like, shape (m, n)
        Gain matrix (rows: variables, columns: parameters).
    variables, parameters : sequence of str, optional
        Row and column names used in the message.
    rtol : float
        Relative singular-value tolerance.

    Returns
    -------
    RankReport
        The report, when the rank is full.

    Examples
    --------
    The second column is twice the first: rank 1, the RGA does not exist.

    >>> check_rank([[1.0, 2.0], [3.0, 4.0]]).rank
    2
    >>> check_rank([[1.0, 2.0], [2.0, 4.0]], variables=["T", "L"], parameters=["kht", "UA"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    trackingbox.errors.AnalysisError: gain matrix (2 variables x 2 parameters) has rank 1 < 2, so the RGA is undefined; ...
    """
    A = _as_matrix(G)
    rows = _names(variables, A.shape[0], "variable")
    cols = _names(parameters, A.shape[1], "parameter")
    rep = rank_report(A, rtol=rtol)
    if rep.full:
        return rep
    parts = [f"gain matrix ({A.shape[0]} variables x {A.shape[1]} parameters) has rank {rep.rank}"
             f" < {min(A.shape)}, so the RGA is undefined"]
    if A.shape[1] > rep.rank and rep.dependent_columns:
        parts.append("parameters whose gain columns depend on the others: "
                     + ", ".join(repr(cols[j]) for j in rep.dependent_columns))
    if A.shape[0] > rep.rank and rep.dependent_rows:
        parts.append("variables whose gain rows depend on the others: "
                     + ", ".join(repr(rows[i]) for i in rep.dependent_rows))
    raise AnalysisError("; ".join(parts))


def relative_gain_array(G: npt.ArrayLike, *, rtol: float = DEFAULT_RTOL,
                        variables: Sequence[str] | None = None,
                        parameters: Sequence[str] | None = None) -> np.ndarray:
    """Relative gain array of a steady-state gain matrix.

    ``Λ = G ∘ (G⁺)ᵀ`` where ``∘`` is the element-wise product and ``G⁺`` the
    Moore-Penrose pseudo-inverse, so non-square matrices work. For a square,
    non-singular ``G`` every row and column of ``Λ`` sums to one.

    Parameters
    ----------
    G : array_like, shape (m, n)
        Steady-state gains, rows = outputs (tracking variables), columns =
        inputs (tracking parameters).
    rtol : float, optional
        Singular values below ``rtol * s_max`` count as zero.
    variables, parameters : sequence of str, optional
        Row/column names, used only in error messages.

    Returns
    -------
    ndarray, shape (m, n)
        The relative gain array.

    Raises
    ------
    AnalysisError
        If ``G`` is rank deficient (``rank < min(m, n)``); the message names the
        dependent columns and rows. Also for empty or non-finite input.

    See Also
    --------
    condition_number, scale_gains

    Examples
    --------
    >>> G = np.array([[1.0, 2.0], [3.0, 4.0]])
    >>> relative_gain_array(G)
    array([[-2.,  3.],
           [ 3., -2.]])
    """
    A = _as_matrix(G)
    check_rank(A, variables=variables, parameters=parameters, rtol=rtol)
    pinv = np.linalg.pinv(A, rcond=rtol)
    return A * pinv.T


def condition_number(G: npt.ArrayLike) -> float:
    """Ratio of the largest to the smallest of the ``min(m, n)`` singular values.

    ``inf`` when the smallest is zero. Large values (say > 100 after scaling)
    mean the gains are nearly dependent: small model errors give large
    parameter moves.

    Parameters
    ----------
    G : array_like, shape (m, n)

    Returns
    -------
    float

    Examples
    --------
    >>> condition_number(np.diag([10.0, 0.1]))
    100.0
    """
    A = _as_matrix(G)
    s = np.linalg.svd(A, compute_uv=False)
    if s[-1] == 0.0:
        return float("inf")
    return float(s[0] / s[-1])


def scale_gains(G: npt.ArrayLike, variable_ranges: npt.ArrayLike | None = None,
                parameter_ranges: npt.ArrayLike | None = None) -> np.ndarray:
    """Dimensionless gains: ``G_s = diag(1/r_y) · G · diag(r_p)``.

    A scaled gain of 0.1 means that moving the parameter over its whole bound
    range moves the variable by a tenth of its range. The RGA of a square
    non-singular matrix does not depend on this scaling, but the RGA of a
    non-square one, the condition number and "negligible gain" tests do.

    Parameters
    ----------
    G : array_like, shape (m, n)
        Gains in engineering units.
    variable_ranges : array_like, shape (m,), optional
        Typical span of each variable (e.g. measured max - min); ones if omitted.
    parameter_ranges : array_like, shape (n,), optional
        ``max - min`` of each parameter's bounds; ones if omitted.

    Returns
    -------
    ndarray, shape (m, n)

    Raises
    ------
    AnalysisError
        If a range is not positive and finite or has the wrong length.

    Examples
    --------
    >>> scale_gains([[2.0]], variable_ranges=[4.0], parameter_ranges=[0.5])
    array([[0.25]])
    """
    A = _as_matrix(G)
    m, n = A.shape
    ry = _ranges(variable_ranges, m, "variable")
    rp = _ranges(parameter_ranges, n, "parameter")
    return A / ry[:, None] * rp[None, :]


def _ranges(r: npt.ArrayLike | None, n: int, kind: str) -> np.ndarray:
    if r is None:
        return np.ones(n)
    arr = np.asarray(r, dtype=float).reshape(-1)
    if arr.size != n:
        raise AnalysisError(f"{arr.size} {kind} ranges given for {n} {kind}s")
    bad = np.flatnonzero(~np.isfinite(arr) | (arr <= 0))
    if bad.size:
        raise AnalysisError(f"{kind} ranges must be positive and finite; entries {bad.tolist()} are "
                            f"{arr[bad].tolist()}")
    return arr


def parameter_ranges(bounds: Sequence[tuple[float, float]]) -> np.ndarray:
    """``max - min`` for each ``(min, max)`` bound pair.

    Examples
    --------
    >>> parameter_ranges([(850.0, 1150.0), (0.5, 1.5)])
    array([300.,   1.])
    """
    arr = np.asarray(bounds, dtype=float).reshape(-1, 2)
    return arr[:, 1] - arr[:, 0]


def variable_ranges(samples: npt.ArrayLike, *, floor: npt.ArrayLike | float = 0.0,
                    trim: float = 0.0) -> np.ndarray:
    """Span of each column of *samples* (NaNs ignored), at least *floor*.

    Parameters
    ----------
    samples : array_like, shape (k, m)
        Measurements of the *m* variables (rows: time).
    floor : float or array_like, shape (m,)
        Lower limit, so a flat-lined signal does not give a zero range.
    trim : float
        Fraction of the samples left out at each end: the span is from the
        ``trim`` to the ``1 - trim`` quantile (0: ``max - min``). A few
        transients (a valve closing in a stoppage's ramp) then do not set the
        scale of a variable that otherwise moves far less.

    Examples
    --------
    >>> variable_ranges([[1.0, 5.0], [3.0, 5.0]], floor=0.5)
    array([2. , 0.5])
    >>> variable_ranges([0.0, 1.0, 2.0, 3.0, 100.0], trim=0.25)  # the outlier does not set the span
    array([2.])
    """
    arr = np.asarray(samples, dtype=float)
    if arr.ndim == 1:
        arr = arr[:, None]
    if not 0.0 <= trim < 0.5:
        raise AnalysisError(f"variable_ranges: trim must be in [0, 0.5), got {trim!r}")
    with np.errstate(all="ignore"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: span 0, then the floor
            if trim > 0.0:
                lo, hi = np.nanquantile(arr, [trim, 1.0 - trim], axis=0)
                span = hi - lo
            else:
                span = np.nanmax(arr, axis=0) - np.nanmin(arr, axis=0)
    span = np.where(np.isfinite(span), span, 0.0)
    return np.maximum(span, np.broadcast_to(np.asarray(floor, dtype=float), span.shape))
