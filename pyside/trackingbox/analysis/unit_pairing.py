"""Pairing per unit, the helpers :func:`~trackingbox.analysis.pairing.choose_pairs` calls: each name's unit,
the cost of the pairs outside the square block (:func:`rest_of`), and why a unit's tag or parameter
is left unpaired.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..errors import AnalysisError
from .blocks import Block, square_rga
from .data_checks import leakage
from .pairing_model import FORBIDDEN, fmt


def unit_lists(units: tuple[Sequence[int | None], Sequence[int | None]] | None, m: int, n: int
                ) -> tuple[list[int | None], list[int | None]]:
    """The unit index per variable and per parameter (all None without *units*)."""
    if units is None:
        return [None] * m, [None] * n
    var_unit, par_unit = (list(units[0]), list(units[1]))
    if len(var_unit) != m or len(par_unit) != n:
        raise AnalysisError(f"units: {len(var_unit)} variable and {len(par_unit)} parameter entries for "
                            f"{m} variables and {n} parameters")
    return var_unit, par_unit


def rest_of(cost: np.ndarray, rows: Sequence[int], cols: Sequence[int], S: np.ndarray, max_leak: float,
             weights: Callable[[Sequence[int]], np.ndarray] | None = None
             ) -> Callable[[frozenset[tuple[int, int]]], tuple[int, float, int]]:
    """``rest(block_pairs) -> (pairs, cost, entangled)`` of :func:`~trackingbox.analysis.blocks.choose_block`:
    the assignment of the other parameters on *cost* (rows: *rows*, columns: *cols*) without the rows
    the block takes, and how many of all the pairs a parameter left unpaired moves by more than
    *max_leak* of its range per range (:func:`leakage` on the scaled gains *S*; 0 when it is inf)."""
    where = {i: a for a, i in enumerate(rows)}

    def rest(taken: frozenset[tuple[int, int]]) -> tuple[int, float, int]:
        c = cost.copy()
        c[[where[i] for i, _ in taken], :] = FORBIDDEN
        r, k = linear_sum_assignment(c)
        ok = c[r, k] < FORBIDDEN
        entangled = 0
        if math.isfinite(max_leak):
            pairs = sorted(taken) + [(rows[int(a)], cols[int(b)]) for a, b in zip(r[ok], k[ok])]
            used = {j for _, j in pairs}
            unpaired = [j for j in cols if j not in used]
            try:
                L = np.abs(leakage(S, [i for i, _ in pairs], [j for _, j in pairs], unpaired))
                if weights is not None and L.size:
                    L = L * weights(unpaired)[None, :]
                entangled = int((L.max(axis=1) > max_leak).sum()) if L.size else 0
            except AnalysisError:   # singular pairs: as bad as every pair entangled
                entangled = len(pairs)
        return int(ok.sum()), float(c[r, k][ok].sum()), entangled

    return rest


def unit_tag_reason(i: int, block: Block | None, S: np.ndarray, variables: Sequence[str],
                     parameters: Sequence[str], var_unit: Sequence[int | None], par_unit: Sequence[int | None],
                     block_cols: Sequence[int], allowed: np.ndarray,
                     why_not: Callable[[int, int], str | None] | None) -> str:
    """Why variable *i*, a tag of a unit, carries none of its unit's parameters (*why_not(i, j)*: the
    data checks' reason against the pair of variable *i* and parameter *j*)."""
    mine = [j for j in block_cols if par_unit[j] == var_unit[i]]
    if not mine:
        return f"a tag of unit [{var_unit[i]}], which has no candidate parameter paired per unit"
    parts = []
    for j in mine:
        k = list(block_cols).index(j)
        if not allowed[k]:
            why = why_not(i, j) if why_not is not None else None
            parts.append(f"the data checks do not allow it for {parameters[j]}" + (f" ({why})" if why else ""))
            continue
        if block is None or j not in block.parameters:
            parts.append(f"{parameters[j]} stays unpaired (see its reason)")
            continue
        a = block.parameters.index(j)
        taker = block.tags[a]
        trial = list(block.tags)
        trial[a] = i
        L = square_rga(S[np.ix_(trial, list(block.parameters))]) if i not in block.tags else None
        if L is None:
            alt = "the block would be singular" if i not in block.tags else "it is taken in the block"
        else:
            alt = (f"with it {parameters[j]}'s relative gain in the block would be {fmt(L[a, a])} "
                   f"and the block's RGA number {fmt(float(np.abs(L - np.eye(len(trial))).sum()))}")
        parts.append(f"{parameters[j]} pairs with {variables[taker]} (relative gain {fmt(block.rga[a, a])} in "
                     f"the block of unit parameters, RGA number {fmt(block.number)}); {alt}")
    return f"a tag of unit [{var_unit[i]}]: " + "; ".join(parts)


def unit_parameter_reason(j: int, own: Sequence[int], block: Block | None, variables: Sequence[str],
                           parameters: Sequence[str], par_unit: Sequence[int | None], allowed: np.ndarray,
                           rows: Sequence[int], excluded: set[int], min_lambda: float) -> str:
    """Why parameter *j* of a unit is left unpaired."""
    unit = par_unit[j]
    if not own:
        return f"paired per unit, and no tracking variable belongs to its unit [{unit}] (twin outputs ending in [{unit}])"
    names = ", ".join(variables[i] for i in own)
    usable = [i for i in own if i not in excluded and allowed[list(rows).index(i)]]
    if not usable:
        return (f"paired per unit, and none of its unit's tags ({names}) is usable: they are at their noise "
                "floor, out of its reach or refused by the predicted tracking (see their reasons)")
    if block is not None:
        for col, best in block.dropped:
            if col != j:
                continue
            tags = ", ".join(variables[i] for i in usable)
            if not best >= min_lambda:
                return (f"paired per unit: on its unit's usable tags ({tags}) its relative gain in the block of "
                        f"unit parameters stays below the {min_lambda:g} a pair needs (at best {fmt(best)}, the "
                        "block singular if nan): its loop would depend on the others'")
            return (f"paired per unit: on its unit's usable tags ({tags}) a pair (its own or one it displaces) could "
                    "not be told apart from a candidate left unpaired (the separation check), or it would take "
                    f"the only tag of another candidate (relative gain in the block at best {fmt(best)})")
    return f"paired per unit; its unit's usable tags ({', '.join(variables[i] for i in usable)}) are taken"
