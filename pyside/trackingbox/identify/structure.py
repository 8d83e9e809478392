"""What a scaled sensitivity matrix can and cannot determine: rank, directions, named combinations.

Pure numerics on arrays (no FMU): :mod:`trackingbox.identify.analysis` feeds
them the sensitivities of a twin on the data.

Scaling
-------
Column ``j`` of the *scaled sensitivity matrix* is ``∂y/∂θ_j`` times

* ``θ_j`` when the parameter's bounds are positive (``log``: the sensitivity to
  a *relative* change, ``∂y/∂ln θ_j``), so that products and ratios of
  parameters are straight lines and "10 %" means the same for every parameter;
* ``max_j - min_j`` otherwise (``range``: a move by its whole bound range),

and each row (one sample of one tag) is divided by that tag's noise standard
deviation ``σ_tag``. For white noise the scaled matrix ``S`` then gives the
Fisher information ``SᵀS`` of the scaled parameters ``z`` (``ln θ`` or
``θ / range``): the standard error along a unit direction ``v`` of ``z`` is
``1 / ‖S v‖``; along a right singular vector it is ``1 / s_i``.

What "determined" means
-----------------------
A direction of ``z`` is *determined* when its 95 % interval (``z_0.975 / s_i``)
is at most :data:`DETERMINED_FRACTION` of the extent the bounds allow along it
(``Σ_j |v_j| w_j`` with ``w_j = ln(max_j / min_j)`` or 1): the data narrow it to
at most half the width the bounds already give. Directions that fail are the
*undetermined subspace*. Separately, the numerical rank counts the singular
values above :data:`RANK_RTOL` of the largest: a direction below it is not seen
at this precision of the sensitivities, whatever the noise (a structural gap:
``R1·C`` and ``R2·C`` of a wall seen through its temperature).

Naming
------
The undetermined subspace, in log coordinates, is brought to reduced row
echelon form and rounded to small rationals (:func:`rational_basis`); where that
fits (within :data:`RATIONAL_TOLERANCE`) the undetermined directions are
exponent vectors and the *determined combinations* are the products and ratios
orthogonal to them, chosen simplest first (fewest parameters, fewest divisions:
:func:`complement_combinations`): "only R1·C and R2·C are determined". An
additive structure (``R1 + R2``) is rational in the parameters' own units
instead, which the caller checks with the directions converted by
:func:`to_linear`. Anything else is reported as the numbers it is.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

Kind = Literal["log", "range"]

#: The 95 % interval of a determined direction spans at most this fraction of the bound box's extent
#: along it (half-width; the full interval is then at most half the width the bounds allow).
DETERMINED_FRACTION = 0.25
#: Singular values below this fraction of the largest count as zero for the numerical rank: the exact
#: sensitivities are accurate to about 1e-4 of their size (see :mod:`trackingbox.sensitivity`), central
#: differences to about 1e-3 at the step used.
RANK_RTOL = 1e-3
#: A parameter takes part in an undetermined direction when its component in the (orthonormal)
#: undetermined subspace has at least this length.
PARTICIPATION = 0.1
#: Largest deviation of a row-reduced undetermined direction from the rational vector it is named by
#: (a structural product is exact to the sensitivities' accuracy, ~1e-4; a loose tolerance would name
#: a generic direction after the nearest small fraction).
RATIONAL_TOLERANCE = 0.01
#: Largest denominator of a rational exponent.
MAX_DENOMINATOR = 4
#: Normal quantile of a two-sided 95 % interval.
Z95 = 1.959963984540054


@dataclass(frozen=True)
class Scaling:
    """How the columns of the sensitivity matrix are scaled (see the module docstring).

    Attributes
    ----------
    kinds
        Per parameter ``"log"`` or ``"range"``.
    factors
        Per parameter the multiplier of ``∂y/∂θ_j``: ``θ_j`` or ``max_j - min_j``.
    widths
        Per parameter the bound box's width in scaled units: ``ln(max/min)`` or 1.
    """

    kinds: tuple[Kind, ...]
    factors: np.ndarray
    widths: np.ndarray

    def to_json(self) -> dict[str, Any]:
        return {"kinds": list(self.kinds), "factors": [float(f) for f in self.factors],
                "widths": [float(w) for w in self.widths]}


def parameter_scaling(x: npt.ArrayLike, lower: npt.ArrayLike, upper: npt.ArrayLike) -> Scaling:
    """The column scaling at the point *x*: ``log`` where the bounds are positive, else ``range``.

    >>> s = parameter_scaling([2.0, 0.5], [1.0, -1.0], [4.0, 1.0])
    >>> s.kinds, s.factors.tolist(), [round(float(w), 4) for w in s.widths]
    (('log', 'range'), [2.0, 2.0], [1.3863, 1.0])
    """
    x, lo, hi = (np.asarray(a, dtype=float) for a in (x, lower, upper))
    kinds: list[Kind] = ["log" if (lo_j > 0 and x_j > 0) else "range" for lo_j, x_j in zip(lo, x)]
    factors = np.array([x_j if k == "log" else hi_j - lo_j for k, x_j, hi_j, lo_j in zip(kinds, x, hi, lo)])
    widths = np.array([math.log(hi_j / lo_j) if k == "log" else 1.0 for k, hi_j, lo_j in zip(kinds, hi, lo)])
    return Scaling(tuple(kinds), factors, widths)


def scale_matrix(jacobian: npt.ArrayLike, scaling: Scaling, row_sigma: npt.ArrayLike) -> np.ndarray:
    """``S = diag(1/σ_row) · J · diag(factors)``; rows with a NaN or a non-positive σ are dropped.

    >>> scale_matrix([[1.0, 2.0], [3.0, 4.0]], parameter_scaling([2.0, 1.0], [1.0, 0.5], [4.0, 2.0]), [1.0, 2.0])
    array([[2., 2.],
           [3., 2.]])
    """
    J = np.asarray(jacobian, dtype=float)
    sigma = np.asarray(row_sigma, dtype=float)
    ok = np.isfinite(sigma) & (sigma > 0) & np.isfinite(J).all(axis=1)
    return J[ok] / sigma[ok, None] * scaling.factors[None, :]


@dataclass(frozen=True)
class Structure:
    """The identifiability of the parameters at one point (see the module docstring).

    Attributes
    ----------
    names
        Parameters (columns).
    singular_values
        Of the scaled matrix, largest first.
    directions
        Principal axes of the confidence ellipsoid as columns, the best determined first (without
        a covariance: the right singular vectors; numerically null ones last).
    half_widths
        95 % half-width along each direction (scaled units; ``inf`` for a numerically null one).
    extents
        The bound box's extent along each direction (scaled units).
    rank
        Singular values above :data:`RANK_RTOL` of the largest.
    determined
        Per direction: its 95 % half-width is at most :data:`DETERMINED_FRACTION` of its extent.
    covariance
        Covariance of the scaled parameters implied by the matrix (pseudo-inverse of ``SᵀS``;
        ``inf`` on the diagonal of parameters in a numerically null direction).
    correlation
        Correlation matrix of the scaled parameters (a null direction regularised at 1e-12 of
        the largest eigenvalue, so its parameters read close to +-1 with each other).
    marginal
        Per parameter its own 95 % half-width (scaled units).
    """

    names: tuple[str, ...]
    singular_values: np.ndarray
    directions: np.ndarray
    half_widths: np.ndarray
    extents: np.ndarray
    rank: int
    determined: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    marginal: np.ndarray

    @property
    def undetermined(self) -> np.ndarray:
        """Orthonormal basis (columns) of the undetermined subspace."""
        return self.directions[:, ~self.determined]

    def participation(self) -> np.ndarray:
        """Per parameter the length of its component in the undetermined subspace (0..1)."""
        u = self.undetermined
        return np.sqrt(np.sum(u * u, axis=1)) if u.size else np.zeros(len(self.names))


def analyse(S: npt.ArrayLike, names: Sequence[str], widths: npt.ArrayLike, *,
            covariance: npt.ArrayLike | None = None, z: float = Z95,
            fraction: float = DETERMINED_FRACTION, rank_rtol: float = RANK_RTOL) -> Structure:
    """The :class:`Structure` of the scaled sensitivity matrix *S* (rows: samples, columns: parameters).

    With *covariance* (of the scaled parameters, e.g. a sandwich estimate that takes the
    residuals' autocorrelation into account) the directions and half-widths come from it
    instead of from ``(SᵀS)^-1``: its eigenvectors, ``z * sqrt(eigenvalue)``.

    Examples
    --------
    ``y = a·b·t`` seen at four times: only the product is determined (log scaling makes
    both columns equal, rank 1, the null direction ``(1, -1)/sqrt(2)``).

    >>> t = np.arange(1.0, 5.0)
    >>> a, b = 2.0, 3.0
    >>> J = np.stack([b * t, a * t], axis=1)            # dy/da, dy/db
    >>> sc = parameter_scaling([a, b], [1.0, 1.0], [4.0, 4.0])
    >>> st = analyse(scale_matrix(J, sc, np.full(4, 0.1)), ["a", "b"], sc.widths)
    >>> st.rank, st.determined.tolist()
    (1, [True, False])
    >>> np.round(np.abs(st.undetermined[:, 0]), 4).tolist()
    [0.7071, 0.7071]
    """
    S = np.asarray(S, dtype=float)
    w = np.asarray(widths, dtype=float)
    n = len(names)
    if S.ndim != 2 or S.shape[1] != n:
        raise ValueError(f"sensitivity matrix has shape {S.shape}, expected (rows, {n})")
    if S.shape[0]:
        _, s, vt = np.linalg.svd(S, full_matrices=False)
    else:
        s, vt = np.zeros(0), np.zeros((0, n))
    if s.size < n:
        s = np.concatenate([s, np.zeros(n - s.size)])
        vt = _complete(vt, n)
    top = float(s[0]) if s.size and s[0] > 0 else 0.0
    zero = s <= rank_rtol * top if top > 0 else np.ones(n, dtype=bool)
    rank = int(np.sum(~zero))
    P, V0 = vt.T[:, ~zero], vt.T[:, zero]
    if covariance is None:
        var_nz, W = 1.0 / s[~zero] ** 2, np.eye(rank)
    else:
        C = np.asarray(covariance, dtype=float)
        if C.shape != (n, n):
            raise ValueError(f"covariance has shape {C.shape}, expected ({n}, {n})")
        var_nz, W = np.linalg.eigh(P.T @ C @ P)
        var_nz = np.clip(var_nz, 0.0, None)
    Q = P @ W
    cov = (Q * var_nz) @ Q.T
    # the numerically null directions: no information at all (infinite variance)
    V = np.concatenate([Q, V0], axis=1)
    half = np.concatenate([z * np.sqrt(var_nz), np.full(V0.shape[1], math.inf)])
    order = np.argsort(half, kind="stable")
    V, half = V[:, order], half[order]
    big = (float(var_nz.max()) if var_nz.size else 1.0) * 1e12
    reg = cov + (V0 * big) @ V0.T
    involved = np.sqrt(np.sum(V0 * V0, axis=1)) > PARTICIPATION if V0.size else np.zeros(n, dtype=bool)
    cov = cov.copy()
    cov[involved, :] = math.inf
    cov[:, involved] = math.inf
    extents = np.abs(V).T @ w
    determined = half <= fraction * extents
    d = np.sqrt(np.clip(np.diag(reg), 1e-300, None))
    corr = np.clip(reg / d[:, None] / d[None, :], -1.0, 1.0)
    marginal = z * np.sqrt(np.diag(cov))
    sv = np.sort(s)[::-1]
    return Structure(tuple(names), sv, V, half, extents, rank, determined, cov, corr, marginal)


def _complete(vt: np.ndarray, n: int) -> np.ndarray:
    """Rows of *vt* completed to an orthonormal basis of R^n."""
    q, _ = np.linalg.qr(np.concatenate([vt.T, np.eye(n)], axis=1))
    return q[:, :n].T


# --------------------------------------------------------------------------- rational directions


def rref(M: npt.ArrayLike, tol: float = 1e-9) -> tuple[np.ndarray, list[int]]:
    """Reduced row echelon form of *M* (partial pivoting) and its pivot columns.

    >>> R, piv = rref([[2.0, 2.0, -2.0]])
    >>> R.tolist(), piv
    ([[1.0, 1.0, -1.0]], [0])
    """
    A = np.array(M, dtype=float, copy=True)
    rows, cols = A.shape
    pivots: list[int] = []
    r = 0
    for c in range(cols):
        if r >= rows:
            break
        p = r + int(np.argmax(np.abs(A[r:, c])))
        if abs(A[p, c]) <= tol:
            continue
        A[[r, p]] = A[[p, r]]
        A[r] /= A[r, c]
        for i in range(rows):
            if i != r:
                A[i] -= A[i, c] * A[r]
        pivots.append(c)
        r += 1
    return A[:r], pivots


def rational_basis(U: npt.ArrayLike, *, tolerance: float = RATIONAL_TOLERANCE,
                   max_denominator: int = MAX_DENOMINATOR) -> list[list[int]] | None:
    """Integer vectors spanning the column space of *U*, or None when it is not close to rational.

    The columns of *U* (a basis of a subspace, one row per parameter) are brought to
    reduced row echelon form, each entry rounded to a fraction with a denominator of at
    most *max_denominator*; None if any entry moves by more than *tolerance*. Each row is
    then scaled to coprime integers with a positive first entry.

    >>> rational_basis(np.array([[0.5773], [0.5774], [-0.5773]]))
    [[1, 1, -1]]
    >>> rational_basis(np.array([[0.8], [-0.6]]))            # 1 : -3/4
    [[4, -3]]
    >>> rational_basis(np.array([[0.857], [0.514]])) is None  # 1 : 0.6: no fraction with denominator <= 4
    True
    """
    U = np.asarray(U, dtype=float)
    if U.size == 0:
        return []
    R, pivots = rref(U.T, tol=1e-6)
    out: list[list[int]] = []
    for row in R:
        fracs = [Fraction(float(v)).limit_denominator(max_denominator) for v in row]
        if max(abs(float(f) - v) for f, v in zip(fracs, row)) > tolerance:
            return None
        lcm = 1
        for f in fracs:
            lcm = lcm * f.denominator // math.gcd(lcm, f.denominator)
        ints = [int(f * lcm) for f in fracs]
        g = 0
        for v in ints:
            g = math.gcd(g, abs(v))
        ints = [v // g for v in ints] if g else ints
        first = next((v for v in ints if v), 0)
        out.append([-v for v in ints] if first < 0 else ints)
    return out


def complement_combinations(null: Sequence[Sequence[int]], n: int, *, limit: int | None = None) -> list[list[int]]:
    """Integer exponent vectors orthogonal to every vector of *null*: the determined combinations.

    As many as ``n - rank(null)`` linearly independent ones, simplest first: fewest
    parameters, then fewest negative exponents (products before ratios), then the
    smallest exponents. Entries up to 2 in size where ``n <= 5``, else up to 1 with at
    most three parameters (*limit* caps the candidates' support).

    >>> complement_combinations([[1, 1, -1]], 3)      # R1, R2, C: R1·C and R2·C
    [[1, 0, 1], [0, 1, 1]]
    >>> complement_combinations([[1, -1]], 2)         # a and b only move together: a·b
    [[1, 1]]
    """
    null_arr = np.array(null, dtype=float).reshape(-1, n)
    want = n - (np.linalg.matrix_rank(null_arr) if null_arr.size else 0)
    if want <= 0:
        return []
    span = 2 if n <= 5 else 1
    support_max = n if n <= 5 else min(n, 3)
    if limit is not None:
        support_max = min(support_max, limit)
    candidates: list[tuple[tuple[int, int, int], list[int]]] = []
    values = [v for v in range(-span, span + 1) if v]
    for k in range(1, support_max + 1):
        for idx in itertools.combinations(range(n), k):
            for vals in itertools.product(values, repeat=k):
                if vals[0] < 0:
                    continue  # a combination and its inverse are equally determined
                a = [0] * n
                for i, v in zip(idx, vals):
                    a[i] = v
                if all(sum(x * y for x, y in zip(a, q)) == 0 for q in null):
                    g = 0
                    for v in a:
                        g = math.gcd(g, abs(v))
                    if g != 1:
                        continue
                    candidates.append(((k, sum(v < 0 for v in a), sum(abs(v) for v in a)), a))
    candidates.sort(key=lambda c: c[0])
    chosen: list[list[int]] = []
    for _, a in candidates:
        trial = np.array(chosen + [a], dtype=float)
        if np.linalg.matrix_rank(trial) > len(chosen):
            chosen.append(a)
            if len(chosen) == want:
                break
    return chosen


def to_linear(U: npt.ArrayLike, x: npt.ArrayLike, scaling: Scaling) -> np.ndarray:
    """Directions of the scaled coordinates (columns of *U*) as directions in the parameters' own units.

    A log coordinate moves ``θ_j`` by ``θ_j · u_j``, a range coordinate by ``range_j · u_j``;
    columns are normalised to unit length.
    """
    U = np.asarray(U, dtype=float)
    D = U * np.asarray(scaling.factors, dtype=float)[:, None]
    norms = np.linalg.norm(D, axis=0)
    return D / np.where(norms > 0, norms, 1.0)


def subspace_angle(A: npt.ArrayLike, B: npt.ArrayLike) -> float:
    """Largest principal angle (rad) between the column spaces of *A* and *B* (pi/2 if dimensions differ).

    >>> round(subspace_angle([[1.0], [0.0]], [[1.0], [1e-3]]), 6)
    0.001
    """
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    if A.shape[1] != B.shape[1]:
        return math.pi / 2
    if A.shape[1] == 0:
        return 0.0
    qa, _ = np.linalg.qr(A)
    qb, _ = np.linalg.qr(B)
    sv = np.linalg.svd(qa.T @ qb, compute_uv=False)
    return float(math.acos(min(1.0, float(sv.min()))))


# --------------------------------------------------------------------------- words


_SUPER = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")


def product_text(exponents: Sequence[int], names: Sequence[str]) -> str:
    """An exponent vector as a product: ``R1·C``, ``R1/R2``, ``a²·b``, ``1/(a·b)``.

    >>> product_text([1, 0, 1], ["R1", "R2", "C"]), product_text([1, -1, 0], ["R1", "R2", "C"])
    ('R1·C', 'R1/R2')
    >>> product_text([2, 1], ["a", "b"]), product_text([-1, -1], ["a", "b"])
    ('a²·b', '1/(a·b)')
    """
    def power(name: str, e: int) -> str:
        return name if e == 1 else f"{name}{str(e).translate(_SUPER)}"

    num = [power(n, e) for n, e in zip(names, exponents) if e > 0]
    den = [power(n, -e) for n, e in zip(names, exponents) if e < 0]
    top = "·".join(num) if num else "1"
    if not den:
        return top
    bottom = den[0] if len(den) == 1 else "(" + "·".join(den) + ")"
    return f"{top}/{bottom}"


def sum_text(coefficients: Sequence[int], names: Sequence[str]) -> str:
    """An integer vector as a linear combination: ``R1 + R2``, ``a - 2·b``.

    >>> sum_text([1, 1], ["R1", "R2"]), sum_text([1, -2], ["a", "b"])
    ('R1 + R2', 'a - 2·b')
    """
    parts: list[str] = []
    for c, n in zip(coefficients, names):
        if not c:
            continue
        term = n if abs(c) == 1 else f"{abs(c)}·{n}"
        parts.append(("- " if c < 0 else "+ ") + term if parts else ("-" if c < 0 else "") + term)
    return " ".join(parts) if parts else "0"


def listing(items: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``.

    >>> listing(["a"]), listing(["a", "b"]), listing(["a", "b", "c"])
    ('a', 'a and b', 'a, b and c')
    """
    items = list(items)
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]
