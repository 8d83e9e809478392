"""Initial equations that give ``pre(v)`` of a discrete variable with an equation of its own.

At initialisation ``pre(v)`` is an unknown of its own (MLS 8.6): the MSL's edge blocks
(``MathBoolean.RisingEdge``, ``ChangingEdge``, ``OnDelay``; ``Logical.Edge``...) state
``initial equation pre(u) = pre_u_start`` while ``u`` keeps its equation (a connection to the
signal it watches), so at the start ``change(u)`` is ``u <> pre_u_start``. The event system read
every initial equation of a discrete variable with ``pre(v)`` as ``v`` (:meth:`.flat_systems.
SystemAssembly._split_discrete`): right for a variable a when-clause assigns (inactive at
initialisation, it keeps ``v = pre(v)``), wrong for one with its own equation: it overrode that
equation, ``u`` stayed ``pre_u_start`` through initialisation and changed at the first event
after it, where a when-clause watching ``change(u)`` then fired (the MSL's ``BooleanNetwork1``:
``triggeredAdd`` counted a change at t = 0 that never happened).

Such an equation (it names ``pre(v)`` of one variable ``v`` that no when-clause assigns, and no
time-varying variable: ``pre(u) = pre_u_start``) is therefore taken out of the discrete initial
equations, and while ``initial()`` holds, the event iteration reads ``pre(v)`` as its value
(:func:`hold_at_initialisation`); after initialisation ``pre(v)`` is ``v`` before each event
iteration step, as always (:mod:`.events`).
"""
from __future__ import annotations

import re

import casadi as ca

from .flat_builtins import solve_scalar_linear


def pre_initial_equations(residuals: list[tuple[ca.MX, str]], pre: dict[str, ca.MX], when_targets: set[str],
                          time_varying: set[str]) -> tuple[list[tuple[ca.MX, str]], dict[str, tuple[ca.MX, ca.MX]]]:
    """Split initial *residuals* into (the others, ``{pre symbol name: (pre symbol, value)}``) for the
    equations that give ``pre(v)`` of a variable with an equation of its own (see the module).

    *pre*: variable name -> its ``pre`` symbol; *when_targets*: names assigned in when-clauses (a last
    subscript removed); *time_varying*: names of the time-varying unknowns (continuous and discrete)."""
    owner = {sym.name(): name for name, sym in pre.items()}
    kept: list[tuple[ca.MX, str]] = []
    values: dict[str, tuple[ca.MX, ca.MX]] = {}
    for r, origin in residuals:
        used = {s.name() for s in ca.symvar(r)}
        pres = [n for n in used if n in owner]
        if len(pres) != 1 or pres[0] in values:
            kept.append((r, origin))
            continue
        var = owner[pres[0]]
        if var in when_targets or re.sub(r"\[[^\]]*\]$", "", var) in when_targets or used & time_varying:
            kept.append((r, origin))
            continue
        value = solve_scalar_linear(r, pre[var])
        if value is None:
            kept.append((r, origin))
            continue
        values[pres[0]] = (pre[var], value)
    return kept, values


def hold_at_initialisation(updates: list[tuple[ca.MX, ca.MX]], values: dict[str, tuple[ca.MX, ca.MX]],
                           initial: ca.MX) -> list[tuple[ca.MX, ca.MX]]:
    """*updates* (the event iteration's assignments) reading each ``pre(v)`` of *values* as its
    initial value while *initial* (the flag of ``initial()``) is 1."""
    if not values:
        return updates
    syms = [sym for sym, _ in values.values()]
    held = [ca.if_else(initial, value, sym) for sym, value in values.values()]
    exprs = ca.substitute([expr for _, expr in updates], syms, held)
    return [(target, expr) for (target, _), expr in zip(updates, exprs)]
