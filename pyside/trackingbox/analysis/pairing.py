"""Choose one tracking parameter per tracking variable from a steady-state gain matrix.

The relative gain array of the (scaled) gain matrix decides: each variable gets
the unused parameter whose relative gain is positive and closest to one, solved
as an assignment problem so that no parameter is used twice. Every variable and
parameter left out gets a reason.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from ..errors import AnalysisError
from .rga import _greedy_independent, condition_number, relative_gain_array, scale_gains

logger = logging.getLogger(__name__)

#: Relative gains above this are flagged: the pairing is sensitive to model error.
LARGE_LAMBDA = 10.0
#: Scaled gains below this fraction of the largest scaled gain count as negligible.
NEGLIGIBLE = 1e-3
#: Rank tolerance on the scaled gain matrix: a parameter whose gain column adds less than
#: this fraction of the largest singular value (or whose column is parallel to a stronger one
#: within ``RANK_RTOL`` rad) cannot be told apart from the others and is left out
#: before the RGA. 1e-2 keeps the condition number of what is paired below ~1e2; on the
#: heat-production bench it separates valves from the pipes in series with them.
RANK_RTOL = 1e-2
_FORBIDDEN = 1e6


@dataclass(frozen=True)
class Pair:
    """One tracking variable driven by one tracking parameter.

    Attributes
    ----------
    variable : str
        Tracking variable (measurement tag or twin output name).
    parameter : str
        Tracking parameter (FMU parameter name).
    lambda_ : float
        Relative gain of the pair.
    gain : float
        Steady-state gain ``d variable / d parameter`` in engineering units.
    time_constant : float
        First-order time constant (s) of the variable's step response to the
        parameter; NaN when unknown.
    """

    variable: str
    parameter: str
    lambda_: float
    gain: float
    time_constant: float = math.nan


@dataclass(frozen=True)
class Pairing:
    """Result of :func:`choose_pairs`.

    Attributes
    ----------
    pairs : tuple of Pair
        Chosen pairs, in the order of the variables.
    left_out : tuple of (str, str)
        ``(name, reason)`` for every variable and parameter not paired.
    warnings : tuple of str
        Negative or large relative gains, poor conditioning.
    variables, parameters : tuple of str
        Row and column names of the matrices below.
    gains : ndarray, shape (m, n)
        Gain matrix in engineering units.
    scaled_gains : ndarray, shape (m, n)
        Gains scaled by variable and parameter ranges.
    rga : ndarray, shape (m, n)
        Relative gain array of the scaled gains over the variables and
        parameters that took part (NaN elsewhere).
    condition_number : float
        Condition number of the scaled gains that took part.
    """

    pairs: tuple[Pair, ...]
    left_out: tuple[tuple[str, str], ...]
    warnings: tuple[str, ...]
    variables: tuple[str, ...] = ()
    parameters: tuple[str, ...] = ()
    gains: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False, repr=False)
    scaled_gains: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False, repr=False)
    rga: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False, repr=False)
    condition_number: float = math.nan

    def parameter_for(self, variable: str) -> str | None:
        """The parameter paired with *variable*, or None."""
        for p in self.pairs:
            if p.variable == variable:
                return p.parameter
        return None


def _fmt(x: float) -> str:
    return f"{x:.3g}"


def choose_pairs(gains: npt.ArrayLike, variables: Sequence[str], parameters: Sequence[str], *,
                 time_constants: npt.ArrayLike | None = None,
                 variable_ranges: npt.ArrayLike | None = None,
                 parameter_ranges: npt.ArrayLike | None = None,
                 negligible: float = NEGLIGIBLE, large: float = LARGE_LAMBDA,
                 rtol: float = RANK_RTOL) -> Pairing:
    """Pair tracking variables with tracking parameters by relative gain.

    Steps: scale the gains (``scale_gains``); leave out parameters and
    variables whose largest scaled gain is below ``negligible`` times the
    largest in the matrix; leave out parameters whose gain column is a linear
    combination of stronger ones (the RGA would be undefined); compute the RGA
    of what remains; assign with :func:`scipy.optimize.linear_sum_assignment`
    on the cost ``|λ - 1|``, negative and zero ``λ`` forbidden.

    Parameters
    ----------
    gains : array_like, shape (m, n)
        ``g_ij = dy_i / dp_j`` in engineering units.
    variables : sequence of str, length m
    parameters : sequence of str, length n
    time_constants : array_like, shape (m, n), optional
        Step-response time constants (s), copied into the chosen pairs.
    variable_ranges, parameter_ranges : array_like, optional
        Scaling ranges (see :func:`~trackingbox.analysis.rga.scale_gains`).
    negligible : float
        Relative threshold for negligible gains.
    large : float
        Relative gains above this are flagged.
    rtol : float
        Rank tolerance on the scaled gains.

    Returns
    -------
    Pairing

    Raises
    ------
    AnalysisError
        If names and matrix shapes disagree.

    Examples
    --------
    >>> p = choose_pairs([[2.0, 0.1], [0.2, 1.0]], ["T1", "T2"], ["a", "b"])
    >>> [(x.variable, x.parameter) for x in p.pairs]
    [('T1', 'a'), ('T2', 'b')]
    """
    G = np.asarray(gains, dtype=float)
    variables = tuple(str(v) for v in variables)
    parameters = tuple(str(p) for p in parameters)
    if G.shape != (len(variables), len(parameters)):
        raise AnalysisError(f"gain matrix has shape {G.shape} but there are {len(variables)} variables "
                            f"and {len(parameters)} parameters")
    m, n = G.shape
    if time_constants is None:
        tau = np.full((m, n), math.nan)
    else:
        tau = np.asarray(time_constants, dtype=float)
        if tau.shape != G.shape:
            raise AnalysisError(f"time-constant matrix has shape {tau.shape}, gains have {G.shape}")
    bad = np.argwhere(~np.isfinite(G))
    if bad.size:
        i, j = bad[0]
        raise AnalysisError(f"gain of {variables[i]!r} to {parameters[j]!r} is not finite ({G[i, j]})")
    S = scale_gains(G, variable_ranges, parameter_ranges)

    left_out: list[tuple[str, str]] = []
    warnings: list[str] = []
    absS = np.abs(S)
    top = float(absS.max()) if absS.size else 0.0
    if top == 0.0:
        for v in variables:
            left_out.append((v, "no candidate parameter changes it (all gains are zero)"))
        for p in parameters:
            left_out.append((p, "changes no tracking variable (all gains are zero)"))
        return Pairing((), tuple(left_out), ("gain matrix is all zeros",), variables, parameters,
                       G, S, np.full((m, n), math.nan), math.inf)

    col_ok = absS.max(axis=0) >= negligible * top
    row_ok = absS.max(axis=1) >= negligible * top
    for j in np.flatnonzero(~col_ok):
        left_out.append((parameters[j], f"negligible gain: its largest scaled gain {_fmt(absS[:, j].max())} "
                                        f"is below {negligible:g} x the largest in the matrix ({_fmt(top)})"))
    for i in np.flatnonzero(~row_ok):
        left_out.append((variables[i], f"no candidate parameter moves it: largest scaled gain "
                                       f"{_fmt(absS[i].max())} is below {negligible:g} x {_fmt(top)}"))
    rows = [int(i) for i in np.flatnonzero(row_ok)]
    cols = [int(j) for j in np.flatnonzero(col_ok)]

    # parallel columns: two parameters with the same effect direction cannot be told apart
    sub = S[np.ix_(rows, cols)]
    norms = np.linalg.norm(sub, axis=0)
    order = [int(k) for k in np.argsort(-norms, kind="stable")]
    drop: set[int] = set()
    for pos, a in enumerate(order if len(rows) > 1 else []):
        if a in drop:
            continue
        for b in order[pos + 1:]:
            if b in drop:
                continue
            cos = min(1.0, abs(float(sub[:, a] @ sub[:, b])) / (norms[a] * norms[b]))
            if math.sqrt(1.0 - cos * cos) < rtol:  # angle between the columns below ~rtol rad
                drop.add(b)
                left_out.append((parameters[cols[b]], "its gain column is parallel to that of "
                                 f"{parameters[cols[a]]} (a linear combination of it): it cannot be "
                                 "told apart from it"))
    cols = [j for k, j in enumerate(cols) if k not in drop]
    sub = S[np.ix_(rows, cols)]
    sv = np.linalg.svd(sub, compute_uv=False)
    rank = int(np.sum(sv > rtol * sv[0]))
    if rank < min(sub.shape):
        kept, dependent = _greedy_independent(sub, rtol, float(sv[0]))
    else:
        kept, dependent = list(range(sub.shape[1])), []
    for k in dependent:
        j = cols[k]
        coef = np.linalg.lstsq(sub[:, kept], sub[:, k], rcond=None)[0]
        weight = np.abs(coef) * np.linalg.norm(sub[:, kept], axis=0)
        top = [kept[q] for q in np.argsort(-weight)[:3] if weight[q] > 1e-3 * weight.max()]
        others = ", ".join(parameters[cols[q]] for q in top)
        left_out.append((parameters[j], "its gain column is (nearly) a linear combination of those of "
                                        f"{others}{' and others' if len(kept) > len(top) else ''}: "
                                        "it cannot be told apart from them"))
    cols = [cols[k] for k in kept]
    sub = S[np.ix_(rows, cols)]

    lam_sub = relative_gain_array(sub, rtol=rtol * 1e-3,
                                  variables=[variables[i] for i in rows],
                                  parameters=[parameters[j] for j in cols])
    lam = np.full((m, n), math.nan)
    lam[np.ix_(rows, cols)] = lam_sub
    cond = condition_number(sub)

    neg = [(variables[rows[a]], parameters[cols[b]], lam_sub[a, b])
           for a, b in np.argwhere(lam_sub < -1e-9)]
    big = [(variables[rows[a]], parameters[cols[b]], lam_sub[a, b])
           for a, b in np.argwhere(lam_sub > large)]
    if neg:
        warnings.append("negative relative gains (pairing there would act against the other loops): "
                        + ", ".join(f"{v}/{p} {_fmt(x)}" for v, p, x in neg[:8])
                        + (" ..." if len(neg) > 8 else ""))
    if big:
        warnings.append(f"large relative gains (> {large:g}; strong interaction, sensitive to model error): "
                        + ", ".join(f"{v}/{p} {_fmt(x)}" for v, p, x in big[:8])
                        + (" ..." if len(big) > 8 else ""))
    if cond > 1e3:
        warnings.append(f"scaled gain matrix is ill-conditioned (condition number {_fmt(cond)}): "
                        "parameter moves will be large for small errors")

    cost = np.where(lam_sub > 1e-9, np.abs(lam_sub - 1.0), _FORBIDDEN)
    r_idx, c_idx = linear_sum_assignment(cost)
    chosen: dict[int, int] = {}
    for a, b in zip(r_idx, c_idx):
        if cost[a, b] < _FORBIDDEN:
            chosen[rows[int(a)]] = cols[int(b)]

    pairs = []
    for i in range(m):
        if i in chosen:
            j = chosen[i]
            pairs.append(Pair(variables[i], parameters[j], float(lam[i, j]), float(G[i, j]), float(tau[i, j])))
            if lam[i, j] > large:
                warnings.append(f"pair {variables[i]}/{parameters[j]} has a large relative gain "
                                f"{_fmt(lam[i, j])}")
    used = set(chosen.values())
    for a, i in enumerate(rows):
        if i in chosen:
            continue
        positive = [(lam_sub[a, b], cols[b]) for b in range(len(cols)) if lam_sub[a, b] > 1e-9]
        if not positive:
            reason = "no parameter has a positive relative gain with it"
        else:
            best_lam, j = min(positive, key=lambda t: abs(t[0] - 1.0))
            taker = next((variables[v] for v, q in chosen.items() if q == j), None)
            reason = (f"no unused parameter with a positive relative gain is left (best was {parameters[j]}, "
                      f"lambda {_fmt(best_lam)}, taken by {taker})" if taker else
                      "fewer usable parameters than variables")
        left_out.append((variables[i], reason))
    for b, j in enumerate(cols):
        if j in used:
            continue
        col = lam_sub[:, b]
        if np.all(col <= 1e-9):
            reason = "no variable has a positive relative gain with it"
        elif len(used) >= len(rows):
            best = int(np.argmin(np.where(col > 1e-9, np.abs(col - 1.0), np.inf)))
            reason = (f"not needed: every variable is paired (closest was {variables[rows[best]]}, "
                      f"lambda {_fmt(col[best])})")
        else:
            reason = "another parameter gave relative gains closer to 1 for the variables it could serve"
        left_out.append((parameters[j], reason))

    for msg in warnings:
        logger.info(msg)
    return Pairing(tuple(pairs), tuple(left_out), tuple(warnings), variables, parameters, G, S, lam, cond)
