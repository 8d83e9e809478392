"""Index reduction: Pantelides' algorithm and a choice of states (dummy derivatives).

A model whose equations constrain variables that also appear differentiated (two inertias joined
rigidly, a position prescribed by a source, capacitors in parallel) is a DAE of higher index: its
equations, solved for the derivatives and algebraic variables, are structurally singular. The
standard cure, as Modelica tools apply it:

1. **Pantelides' algorithm** (1988) finds the equations that must be differentiated: it matches
   each equation to a variable of highest derivative order, and where no augmenting path exists it
   differentiates the equations and variables on the path tried and goes on with the derivative.
   Differentiating an equation is symbolic, by the chain rule: d/dt f(t, v) = df/dt + sum df/dv v'
   (CasADi's directional derivative), with held values (parameters, discrete variables, frozen
   relations) constant between events.
2. **State selection** (dummy derivatives, Mattsson and Söderlind 1993): of the variables that have
   a derivative in the augmented system, as many become states as there are variables more than
   equations, chosen so that the augmented system stays structurally solvable for all the others
   (a greedy choice by ``stateSelect`` (always, prefer, default, avoid; never is never a state),
   original states first); the other variables and the derivatives not of a state ("dummy
   derivatives") are algebraic unknowns.

The result is an index-1 system for the ordinary causalisation. A model that stays singular after
differentiation (an equation missing, or one too many) is not repaired: the caller reports it.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field

import casadi as ca

MAX_GROWTH = 6
"""Give up when the augmented system has this many times the original equations (a model that is
singular, not of higher index, would make Pantelides' algorithm differentiate forever)."""

STATE_SELECT = {"Always": 0, "Prefer": 1, "Default": 2, "Avoid": 3, "Never": 9}


class IndexError_(Exception):
    """Index reduction is not possible (the message says why)."""


@dataclass
class Reduced:
    """The index-1 system: all equations (original and differentiated), the states chosen, and the
    derivative variables created (name, symbol)."""

    residuals: list[tuple[ca.MX, str]]
    states: list[str]
    derivative: dict[str, ca.MX]
    created: list[tuple[str, ca.MX]] = field(default_factory=list)
    differentiated: list[str] = field(default_factory=list)


def reduce_index(residuals: list[tuple[ca.MX, str]], states: dict[str, ca.MX], derivative: dict[str, ca.MX],
                 algebraics: dict[str, ca.MX], time: ca.MX, inputs: set[str],
                 preference: dict[str, str]) -> Reduced:
    """Pantelides' algorithm and state selection (see the module docstring).

    *states*/*derivative*: the variables that appear differentiated and their derivative symbols;
    *algebraics*: the other unknowns; *inputs*: names of variables that cannot be differentiated
    (the FMU's inputs); *preference*: ``stateSelect`` by variable name.
    """
    names: list[str] = []
    syms: list[ca.MX] = []
    A: list[int] = []  # derivative variable of each variable, or -1
    original: list[bool] = []
    index: dict[str, int] = {}

    def add_var(name: str, sym: ca.MX, is_original: bool) -> int:
        index[name] = len(names)
        names.append(name)
        syms.append(sym)
        A.append(-1)
        original.append(is_original)
        return index[name]

    for name, sym in states.items():
        j = add_var(name, sym, True)
        A[j] = add_var(derivative[name].name(), derivative[name], False)
    for name, sym in algebraics.items():
        add_var(name, sym, True)

    exprs: list[ca.MX] = [r for r, _ in residuals]
    origins: list[str] = [o for _, o in residuals]
    B: list[int] = [-1] * len(exprs)
    incid: list[list[int]] = [_incidence(e, index) for e in exprs]
    n_original = len(exprs)
    limit = MAX_GROWTH * max(n_original, 1)

    def new_derivative(j: int) -> int:
        base = names[j]
        name = f"der({base})"
        k = 2
        while name in index:  # never reuse a name
            name = f"der({base})#{k}"
            k += 1
        return add_var(name, ca.MX.sym(name), False)

    def differentiate(i: int) -> int:
        expr = exprs[i]
        js = incid[i]
        for s in ca.symvar(expr):
            if s.name() in inputs:
                raise IndexError_(f"the equation {origins[i]} would have to be differentiated, and with it the input "
                                  f"{s.name()}, whose derivative the FMU does not have")
        for j in js:
            if A[j] < 0:
                A[j] = new_derivative(j)
        d = ca.jacobian(expr, time) if ca.depends_on(expr, time) else ca.MX(0)
        if js:
            d = d + ca.jtimes(expr, ca.vertcat(*[syms[j] for j in js]), ca.vertcat(*[syms[A[j]] for j in js]))
        exprs.append(d)
        origins.append(f"d/dt of {origins[i]}")
        B.append(-1)
        incid.append(_incidence(d, index))
        B[i] = len(exprs) - 1
        if len(exprs) > limit:
            raise IndexError_("differentiating the equations does not end (the model is singular, not of "
                              "higher index)")
        return B[i]

    assign: list[int] = []  # variable -> equation

    def ensure() -> None:
        while len(assign) < len(names):
            assign.append(-1)

    old_limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(old_limit, 20000))
    try:
        for k in range(n_original):
            i = k
            while True:
                ensure()
                colour_e: set[int] = set()
                colour_v: set[int] = set()
                if _augment(i, incid, A, assign, colour_e, colour_v):
                    break
                for j in list(colour_v):
                    if A[j] < 0:
                        A[j] = new_derivative(j)
                for eq in sorted(colour_e):
                    differentiate(eq)
                ensure()
                for j in colour_v:
                    assign[A[j]] = B[assign[j]]
                i = B[i]
        ensure()
        return _select(names, syms, A, original, exprs, origins, incid, n_original, states, preference)
    finally:
        sys.setrecursionlimit(old_limit)


def _select(names: list[str], syms: list[ca.MX], A: list[int], original: list[bool], exprs: list[ca.MX],
            origins: list[str], incid: list[list[int]], n_original: int, states: dict[str, ca.MX],
            preference: dict[str, str]) -> Reduced:
    """The choice of states on the augmented system (see the module docstring)."""
    n_states = len(names) - len(exprs)
    # state selection: candidates are original variables that have a derivative in the system
    candidates = [j for j in range(len(names)) if A[j] >= 0 and original[j]
                  and STATE_SELECT.get(preference.get(names[j], "Default"), 2) < 9]
    was_state = set(states)
    candidates.sort(key=lambda j: (STATE_SELECT.get(preference.get(names[j], "Default"), 2),
                                   0 if names[j] in was_state else 1, j))
    matching = _match(incid, len(names), set())
    if matching is None:
        raise IndexError_("the differentiated equations are still singular")
    chosen: list[int] = []
    removed: set[int] = set()
    for c in candidates:
        if len(chosen) == n_states:
            break
        trial = _match(incid, len(names), removed | {c}, start=matching)
        if trial is not None:
            removed.add(c)
            chosen.append(c)
            matching = trial
    if len(chosen) != n_states:
        raise IndexError_(f"no choice of {n_states} states leaves the other variables determined")
    created = [(names[j], syms[j]) for j in range(len(names)) if not original[j]]
    return Reduced(
        residuals=list(zip(exprs, origins)),
        states=[names[j] for j in chosen],
        derivative={names[j]: syms[A[j]] for j in chosen},
        created=[(n, s) for n, s in created],
        differentiated=[origins[i] for i in range(n_original, len(exprs))],
    )


def max_matching(incid: list[list[int]]) -> int:
    """The size of a maximum matching of equations (their incidence lists) to variables."""
    eq_of: dict[int, int] = {}

    def augment(e: int, seen: set[int]) -> bool:
        for v in incid[e]:
            if v in seen:
                continue
            seen.add(v)
            if v not in eq_of or augment(eq_of[v], seen):
                eq_of[v] = e
                return True
        return False

    return sum(1 for e in range(len(incid)) if augment(e, set()))


def _incidence(expr: ca.MX, index: dict[str, int]) -> list[int]:
    return sorted({index[s.name()] for s in ca.symvar(expr) if s.name() in index})


def _augment(i: int, incid: list[list[int]], A: list[int], assign: list[int], colour_e: set[int],
             colour_v: set[int]) -> bool:
    colour_e.add(i)
    for j in incid[i]:
        if A[j] < 0 and assign[j] < 0:
            assign[j] = i
            return True
    for j in incid[i]:
        if A[j] < 0 and j not in colour_v:
            colour_v.add(j)
            if _augment(assign[j], incid, A, assign, colour_e, colour_v):
                assign[j] = i
                return True
    return False


def _match(incid: list[list[int]], n_vars: int, excluded: set[int],
           start: dict[int, int] | None = None) -> dict[int, int] | None:
    """An equation-saturating matching (equation -> variable) avoiding *excluded* variables, or None.
    Starts from *start* (kept where it avoids them), augmenting the equations left."""
    eq_of: dict[int, int] = {}
    var_of: dict[int, int] = {}
    if start:
        for e, v in start.items():
            if v not in excluded:
                var_of[e] = v
                eq_of[v] = e

    def augment(e: int, seen: set[int]) -> bool:
        for v in incid[e]:
            if v in excluded or v in seen:
                continue
            seen.add(v)
            if v not in eq_of or augment(eq_of[v], seen):
                eq_of[v] = e
                var_of[e] = v
                return True
        return False

    for e in range(len(incid)):
        if e not in var_of:
            if not augment(e, set()):
                return None
    return var_of


__all__ = ["IndexError_", "Reduced", "max_matching", "reduce_index"]
