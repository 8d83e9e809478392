"""Structural analysis of an equation system: matching and block ordering.

Given, for each equation, the set of unknowns it contains, :func:`blt` assigns
one unknown to each equation (maximum bipartite matching) and orders the
equations into strongly connected blocks, each block after every block it
depends on (block lower triangular form). A block of size one is a single
equation in a single unknown; larger blocks are algebraic loops.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching


class StructuralError(ValueError):
    """The system is structurally singular (no complete matching)."""

    def __init__(self, message: str, equations: list[int], unknowns: list[int]):
        super().__init__(message)
        self.equations = equations
        self.unknowns = unknowns


@dataclass(frozen=True)
class Block:
    """Equations solved together for their matched unknowns."""

    equations: tuple[int, ...]
    unknowns: tuple[int, ...]


def match(incidence: Sequence[Sequence[int]], n_unknowns: int) -> np.ndarray:
    """Match each equation to one unknown it contains.

    Returns ``assign`` with ``assign[i]`` the unknown of equation ``i``.
    Raises :class:`StructuralError` naming the equations and unknowns left over.

    >>> match([[0, 1], [0]], 2).tolist()
    [1, 0]
    """
    n_eq = len(incidence)
    rows = [i for i, cols in enumerate(incidence) for _ in cols]
    cols = [c for cs in incidence for c in cs]
    graph = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_eq, n_unknowns))
    assign = np.asarray(maximum_bipartite_matching(graph, perm_type="column"))
    free_eqs = [i for i in range(n_eq) if assign[i] < 0]
    used = set(int(a) for a in assign if a >= 0)
    free_unknowns = [j for j in range(n_unknowns) if j not in used]
    if free_eqs or free_unknowns:
        raise StructuralError("structurally singular system", free_eqs, free_unknowns)
    return assign


def blt(incidence: Sequence[Sequence[int]], n_unknowns: int) -> list[Block]:
    """Order a square system into blocks, dependencies first.

    Parameters
    ----------
    incidence:
        ``incidence[i]`` lists the unknowns equation ``i`` contains.
    n_unknowns:
        Number of unknowns (must equal the number of equations).

    Returns
    -------
    list of Block
        Each block comes after every block whose unknowns it uses.

    >>> [b.unknowns for b in blt([[1], [0, 2], [2, 0, 1]], 3)]
    [(1,), (0, 2)]
    """
    n_eq = len(incidence)
    if n_eq != n_unknowns:
        raise StructuralError(
            f"{n_eq} equations for {n_unknowns} unknowns", list(range(n_eq)), list(range(n_unknowns))
        )
    assign = match(incidence, n_unknowns)
    eq_of_unknown = np.empty(n_unknowns, dtype=int)
    eq_of_unknown[assign] = np.arange(n_eq)
    # Equation i depends on equation eq_of_unknown[v] for every other unknown v it uses.
    deps = [[int(eq_of_unknown[v]) for v in incidence[i] if v != assign[i]] for i in range(n_eq)]
    components = _tarjan(deps)
    return [
        Block(tuple(sorted(comp)), tuple(int(assign[i]) for i in sorted(comp))) for comp in components
    ]


def _tarjan(deps: list[list[int]]) -> list[list[int]]:
    """Strongly connected components of ``i -> deps[i]``, each after those it reaches.

    Iterative Tarjan: components are emitted when their root finishes, which
    is after every component reachable from it, so dependencies come first.
    """
    n = len(deps)
    index = [-1] * n
    low = [0] * n
    on_stack = [False] * n
    stack: list[int] = []
    out: list[list[int]] = []
    counter = 0
    for root in range(n):
        if index[root] >= 0:
            continue
        work = [(root, 0)]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack[root] = True
        while work:
            node, pos = work[-1]
            if pos < len(deps[node]):
                work[-1] = (node, pos + 1)
                nxt = deps[node][pos]
                if index[nxt] < 0:
                    index[nxt] = low[nxt] = counter
                    counter += 1
                    stack.append(nxt)
                    on_stack[nxt] = True
                    work.append((nxt, 0))
                elif on_stack[nxt]:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    member = stack.pop()
                    on_stack[member] = False
                    comp.append(member)
                    if member == node:
                        break
                out.append(comp)
    return out
