"""Pairing per unit: each parameter of a unit (an effect of a train) with one of that unit's own tags.

A multi-effect evaporator is a chain: the vapour of effect k is the steam of effect k+1, so
the fouling of any effect moves the pressures of every effect upstream of it (its steam
chest, and through the chain every chest before it) by similar amounts. The whole train's
gain matrix then has many nearly parallel rows (effect k's vapour pressure is effect k+1's
steam-chest pressure seen through a vapour line), and the relative gain array of the tall
matrix (its pseudo-inverse spread over every tag) is ill-conditioned: on the 7-effect
train it put effect 6's fouling on effect 2's steam chest with lambda 143 and the pairing
found no usable pairs. A process modeller pairs decentrally instead: each effect's
fouling with an instrument of that effect, and checks the interaction of those loops on
the square block they form. With the steam-chest pressures the block is close to
triangular (effect k's chest moves with the fouling of effects k and after, hardly with
those before), and the relative gain array of a triangular matrix is the identity: the
loops interact one way only and each can be closed on its own.

:func:`choose_block` does that for the parameters of the units a spec names
(``[pairing] units = ["effect"]``): a parameter ``effect[k].<name>`` may pair only with a
tag whose twin output carries the same index (``PI_steamChest[k]``, ``TI_body[k]``, ...),
and of all such choices, one tag per parameter, the one whose square relative gain array
is closest to the identity (smallest RGA number ``sum |Lambda - I|``, Skogestad and
Postlethwaite's pairing rule), every relative gain of a pair at least ``min_lambda``. The
other parameters are paired on the relative gains of the whole matrix as before; the two
are chosen together (the most pairs first, see :func:`choose_block`'s *rest*).
"""
from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

#: A parameter of an indexed unit: ``effect[3].Rf`` (family ``effect``, index 3).
UNIT_PARAMETER = re.compile(r"^(?P<family>[A-Za-z_][A-Za-z0-9_]*)\[(?P<index>\d+)\]\.")
#: A twin output of an indexed unit: ``PI_steamChest[3]`` (index 3).
UNIT_OUTPUT = re.compile(r"\[(?P<index>\d+)\]$")
#: Largest number of tag combinations :func:`choose_block` tries one by one; above it, a
#: coordinate descent (one parameter's tag changed at a time) from the strongest own tags.
EXHAUSTIVE = 5000
#: A block whose condition number exceeds this counts as singular (no relative gain array).
SINGULAR = 1e12


def parameter_unit(name: str, families: Iterable[str]) -> int | None:
    """Index of the unit parameter *name* belongs to, if its family is one of *families*.

    Examples
    --------
    >>> parameter_unit("effect[3].Rf", ["effect"]), parameter_unit("transferValve[3].capacity", ["effect"])
    (3, None)
    """
    m = UNIT_PARAMETER.match(name)
    return int(m["index"]) if m and m["family"] in set(families) else None


def output_unit(variable: str) -> int | None:
    """Index of the unit a twin output belongs to (its trailing ``[k]``), or None.

    Examples
    --------
    >>> output_unit("PI_steamChest[2]"), output_unit("DI_product")
    (2, None)
    """
    m = UNIT_OUTPUT.search(variable)
    return int(m["index"]) if m else None


def square_rga(A: npt.ArrayLike) -> np.ndarray | None:
    """Relative gain array ``A * inv(A)^T`` of a square matrix, or None when it is singular.

    Examples
    --------
    >>> square_rga([[1.0, 5.0], [0.0, 2.0]]) + 0.0   # triangular: the identity
    array([[1., 0.],
           [0., 1.]])
    """
    M = np.asarray(A, dtype=float)
    if M.ndim != 2 or M.shape[0] != M.shape[1] or M.size == 0 or not np.isfinite(M).all():
        return None
    if not np.linalg.cond(M) < SINGULAR:
        return None
    return M * np.linalg.inv(M).T


def rga_number(L: npt.ArrayLike) -> float:
    """``sum |L - I|``: 0 for a block whose loops do not interact.

    Examples
    --------
    >>> rga_number([[2.0, -1.0], [-1.0, 2.0]])
    4.0
    """
    M = np.asarray(L, dtype=float)
    return float(np.abs(M - np.eye(M.shape[0])).sum())


@dataclass(frozen=True)
class Block:
    """The chosen block: ``tags[a]`` (a row of the gain matrix) paired with ``parameters[a]`` (a column).

    Attributes
    ----------
    parameters, tags : tuple of int
        Columns and rows of the gain matrix, in pairs.
    rga : ndarray, shape (k, k)
        Relative gain array of the square block (rows: *tags*, columns: *parameters*).
    dropped : tuple of (int, float)
        Parameters (columns) with candidates that the choice leaves unpaired, each with its largest
        relative gain in the block on any of its candidates free, beside the chosen pairs (NaN: none,
        or the block singular).
    """

    parameters: tuple[int, ...]
    tags: tuple[int, ...]
    rga: np.ndarray
    dropped: tuple[tuple[int, float], ...] = ()

    @property
    def number(self) -> float:
        """RGA number of the block."""
        return rga_number(self.rga) if self.rga.size else 0.0

    def lambda_of(self, column: int) -> float:
        """Relative gain of *column*'s pair in the block."""
        a = self.parameters.index(column)
        return float(self.rga[a, a])


#: ``rest(block_pairs) -> (pairs, cost, entangled)``, see :func:`choose_block`.
Rest = Callable[[frozenset[tuple[int, int]]], tuple[int, float, int]]
#: Sort key of a choice: (invalid, entangled, -pairs, cost, -strength); smaller is better.
Key = tuple[int, int, int, float, float]
Cache = dict[frozenset[tuple[int, int]], tuple[int, float, int]]


def _score(S: np.ndarray, cols: Sequence[int], rows: Sequence[int | None], min_lambda: float,
           rest: Rest | None, cache: Cache) -> tuple[Key, np.ndarray | None]:
    """Sort key of a choice (*rows*: a row per column, None: the column left unpaired) and its block's
    relative gain array: (any relative gain below *min_lambda*, pairs that fail the separation check,
    -pairs in all, RGA number + the rest's cost, -the pairs' scaled gains)."""
    pairs = [(r, c) for r, c in zip(rows, cols) if r is not None]
    taken = frozenset(pairs)
    if rest is not None and taken not in cache:
        cache[taken] = rest(taken)
    n_rest, c_rest, entangled = cache[taken] if rest is not None else (0, 0.0, 0)
    strength = float(sum(abs(S[r, c]) for r, c in pairs))
    if not pairs:
        return (0, entangled, -n_rest, c_rest, 0.0), np.zeros((0, 0))
    L = square_rga(S[np.ix_([r for r, _ in pairs], [c for _, c in pairs])])
    if L is None:
        return (1, entangled, -(len(pairs) + n_rest), math.inf, -strength), None
    diag = np.diag(L)
    invalid = int(not (diag >= min_lambda).all())
    return (invalid, entangled, -(len(pairs) + n_rest), rga_number(L) + c_rest, -strength), L


def choose_block(scaled: npt.ArrayLike, candidates: Mapping[int, Sequence[int]], *, min_lambda: float = 0.1,
                 rest: Rest | None = None, exhaustive: int = EXHAUSTIVE) -> Block:
    """One tag per parameter, from its *candidates*, so that the block's loops interact least.

    Every parameter may also stay unpaired. Of all choices the best is, in this order: every pair's
    relative gain in the block at least *min_lambda*; the fewest pairs that fail the separation
    check (see *rest*); the most pairs in all; the smallest RGA number of the block (plus the
    rest's cost); the largest scaled gains of the pairs (the clearest indicators).

    Parameters
    ----------
    scaled : array_like, shape (m, n)
        Scaled gain matrix (the square block's relative gains do not depend on the scaling).
    candidates : mapping int -> sequence of int
        Column (parameter) -> the rows (tags) it may pair with: its unit's own tags that the data
        checks allow. A column without candidates is left out.
    min_lambda : float
        Smallest relative gain of a pair in the block.
    rest : callable, optional
        ``rest(block_pairs) -> (pairs, cost, entangled)`` for the block's ``(row, column)`` pairs:
        how many pairs the other parameters get on the rows the block leaves, the sum of their
        ``|lambda - 1|``, and how many of all those pairs would fail the separation check
        (:func:`~trackingbox.analysis.pairing.leakage`: a pair whose parameter follows a candidate
        left unpaired; 0 without the check). So a unit parameter does not take the tag another
        candidate is told apart on (the level controller's output of a valve whose capacity is a
        candidate), which would leave that candidate unpaired and followed by the loops that see it.
    exhaustive : int
        Every combination is tried up to this many; above it a coordinate descent from each
        parameter's strongest own tag (by scaled gain).

    Returns
    -------
    Block
        The pairs chosen; :attr:`Block.dropped` the parameters with candidates left unpaired, each
        with its largest relative gain in the block on any of its candidates (NaN: singular).

    Examples
    --------
    Two effects; tags 0, 1 belong to the first parameter, tag 2 to the second. Tag 0 is moved by
    both parameters alike (its relative gain with the first: 1 / (1 - 1 x 1 / (1 x 2)) = 2),
    tag 1 by the first only (block triangular: relative gains 1):

    >>> S = [[1.0, 1.0], [1.0, 0.0], [1.0, 2.0]]
    >>> b = choose_block(S, {0: [0, 1], 1: [2]})
    >>> b.tags, b.parameters, round(b.number, 12)
    ((1, 2), (0, 1), 0.0)
    """
    S = np.asarray(scaled, dtype=float)
    cand = {int(j): [int(i) for i in dict.fromkeys(rows)] for j, rows in candidates.items() if len(rows)}
    cols = sorted(cand)
    if not cols:
        return Block((), (), np.zeros((0, 0)))
    cache: Cache = {}
    key, rows, L = _search(S, cols, cand, min_lambda, rest, cache, exhaustive)
    pairs = [(r, c) for r, c in zip(rows, cols) if r is not None]
    dropped = []
    for c, r in zip(cols, rows):
        if r is not None:
            continue
        best = math.nan
        for i in cand[c]:
            if i in {p for p, _ in pairs}:
                continue
            trial = pairs + [(i, c)]
            Lt = square_rga(S[np.ix_([p for p, _ in trial], [q for _, q in trial])])
            if Lt is not None and not (Lt[-1, -1] <= best):
                best = float(Lt[-1, -1])
        dropped.append((c, best))
    return Block(tuple(c for _, c in pairs), tuple(r for r, _ in pairs),
                 L if L is not None else np.zeros((0, 0)), tuple(dropped))


def _search(S: np.ndarray, cols: list[int], cand: dict[int, list[int]], min_lambda: float, rest: Rest | None,
            cache: Cache, exhaustive: int) -> tuple[Key, list[int | None], np.ndarray | None]:
    """Best choice (a row or None per column, rows distinct): every combination, or a coordinate descent."""
    options = {j: [*cand[j], None] for j in cols}
    size = math.prod(len(options[j]) for j in cols)
    best: tuple[Key, list[int | None], np.ndarray | None]
    if size <= exhaustive:
        best = ((2, 0, 0, math.inf, 0.0), [None] * len(cols), None)
        for combo in itertools.product(*(options[j] for j in cols)):
            taken = [r for r in combo if r is not None]
            if len(set(taken)) < len(taken):
                continue
            key, L = _score(S, cols, combo, min_lambda, rest, cache)
            if key < best[0]:
                best = (key, list(combo), L)
        return best
    # coordinate descent from each parameter's strongest own tag not yet taken
    rows: list[int | None] = []
    for j in cols:
        free = [i for i in sorted(cand[j], key=lambda i: -abs(S[i, j])) if i not in rows]
        rows.append(free[0] if free else None)
    key, L = _score(S, cols, rows, min_lambda, rest, cache)
    best = (key, list(rows), L)
    improved = True
    while improved:
        improved = False
        for a, j in enumerate(cols):
            for i in options[j]:
                if i == best[1][a] or (i is not None and i in best[1]):
                    continue
                trial = list(best[1])
                trial[a] = i
                key, L = _score(S, cols, trial, min_lambda, rest, cache)
                if key < best[0]:
                    best, improved = (key, trial, L), True
    return best
