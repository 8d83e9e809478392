"""Initial equations among several discrete variables and their ``pre`` values (MLS 8.6).

At initialisation every discrete variable ``v`` and its ``pre(v)`` are unknowns of their own; the
model's equations hold (a when-clause not fired by ``initial()`` gives ``v = pre(v)``), the
initial equations hold, and a ``pre(v)`` that nothing else determines is ``v``'s start value.
The event system's first reading (:meth:`.flat_systems.SystemAssembly._initial_discrete`) solves
each initial equation alone with ``pre(v)`` read as ``v``; that cannot do the MSL's
``StateGraph`` steps, whose initial equations relate ``pre`` values only and are closed through
the model's equations::

    localActive = pre(newActive);          // equation of PartialStep
    active = localActive;                  // equation of InitialStep / Step
    pre(newActive) = pre(localActive);     // initial equations of PartialStep
    pre(oldActive) = pre(localActive);
    active = true;                         // initial equation of InitialStep (Step: false)

Read with ``pre(v)`` as ``v``, the first of these is ``newActive = localActive``: two unknowns,
and no initial equation alone says which step is active. Here the whole discrete initialisation
problem is solved at once: unknowns the discrete variables and the ``pre`` symbols, equations the
model's discrete equations as they read at initialisation, the initial equations with ``pre``
kept, and ``pre(v) = start`` for each ``pre`` value left undetermined (added where it raises the
structural rank). It is sorted into blocks and each block solved for its one unknown (Boolean
equations ``a = b``, ``a = (b and not c)``... are explicit); a block of several unknowns is
refused, naming them. The ``pre`` values the equations determine (not their start values) are what
the event iteration reads for ``pre(v)`` while ``initial()`` holds (:func:`.initial_pre.
hold_at_initialisation`): with them held, the model's own equations give every discrete variable its
initial value (the InitialStep active, the others not), and after initialisation ``pre(v)`` is ``v``
before each event iteration step, as always (:mod:`.events`).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from .causalize import StructuralError, blt
from .events import EventSystem
from .flat_builtins import solve_scalar_linear
from .index import max_matching


@dataclass
class InitialDiscreteError(Exception):
    """The discrete initialisation problem cannot be solved block by block: *what* names the cause,
    *origins* the equations involved (as :func:`origin_text` gives them), *initial* the positions of
    the initial equations among them in the list given to :func:`solve_initial_discrete`."""

    what: str
    origins: list[str]
    initial: list[int]

    def __str__(self) -> str:
        return self.what


def at_initialisation(exprs: list[ca.MX], ev: EventSystem) -> list[ca.MX]:
    """*exprs* as they read at initialisation: ``initial()`` true, no sample instant, a relation its
    value, a when condition its value with no rising edge unless ``initial()`` makes one."""
    syms: list[ca.MX] = [ev.initial]
    vals: list[ca.MX] = [ca.MX(1)]
    for c in ev.conditions:
        syms.append(c.sym)
        vals.append(c.value)
    for s in ev.samples:
        syms.append(s.sym)
        vals.append(ca.MX(0))
    for w in ev.whens:
        syms += [w.sym, w.pre]
        vals += [w.value, ca.MX(0)]
    # the values may name the flags themselves (a relation on initial()): substitute twice
    out = ca.substitute(list(exprs), syms, vals)
    return list(ca.substitute(out, syms, vals))


def solve_initial_discrete(initial: list[tuple[ca.MX, str]], model: list[tuple[ca.MX, str]],
                           unknowns: list[ca.MX], pre: dict[str, ca.MX], starts: dict[str, float],
                           ev: EventSystem) -> dict[str, tuple[ca.MX, ca.MX]]:
    """The ``pre`` values the discrete initialisation problem determines (see the module), as
    ``{pre symbol name: (pre symbol, value)}``.

    *initial*: the discrete initial equations with ``pre`` kept (and ``pre(v) - value`` for the
    values already taken out, :func:`.initial_pre.pre_initial_equations`); *model*: the model's
    discrete equations (when-clauses included); *unknowns*: the discrete variables' symbols;
    *pre*: variable name -> its ``pre`` symbol; *starts*: variable name -> start value."""
    pres = list(pre.items())
    syms = list(unknowns) + [p for _, p in pres]
    position = {s.name(): i for i, s in enumerate(syms)}
    model_at_start = at_initialisation([r for r, _ in model], ev)
    eqs = list(initial) + [(r, origin) for r, (_, origin) in zip(model_at_start, model)]

    def incidence(r: ca.MX) -> list[int]:
        return sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position})

    incid = [incidence(r) for r, _ in eqs]
    rank = max_matching(incid)
    defaults = set()
    for name, p in pres:  # pre(v) = start where nothing else determines it
        if rank == len(syms):
            break
        trial = incid + [[position[p.name()]]]
        if max_matching(trial) > rank:
            incid, rank = trial, rank + 1
            eqs.append((p - starts.get(name, 0.0), f"start value of pre({name})"))
            defaults.add(p.name())
    try:
        blocks = blt(incid, len(syms))
    except StructuralError as exc:
        names = [syms[j].name() for j in exc.unknowns][:8]
        raise InitialDiscreteError(
            f"{len(eqs)} equations for {len(syms)} discrete unknowns and pre values"
            + (f", not determined: {', '.join(names)}" if names else ""),
            sorted({eqs[i][1] for i in exc.equations}), sorted(i for i in exc.equations if i < len(initial))) from None
    solved_syms: list[ca.MX] = []
    solved_vals: list[ca.MX] = []
    held: dict[str, tuple[ca.MX, ca.MX]] = {}
    for block in blocks:
        if len(block.unknowns) != 1:
            names = ", ".join(syms[j].name() for j in block.unknowns[:8])
            raise InitialDiscreteError(f"a loop among discrete initial values ({names})",
                                       sorted({eqs[i][1] for i in block.equations}),
                                       sorted(i for i in block.equations if i < len(initial)))
        r, origin = eqs[block.equations[0]]
        u = syms[block.unknowns[0]]
        if solved_syms:
            r = ca.substitute([r], solved_syms, solved_vals)[0]
        value = solve_scalar_linear(r, u)
        if value is None:
            raise InitialDiscreteError(f"an initial value of {u.name()} that its equation does not give "
                                       f"explicitly", [origin],
                                       [block.equations[0]] if block.equations[0] < len(initial) else [])
        solved_syms.append(u)
        solved_vals.append(value)
        if block.unknowns[0] >= len(unknowns) and u.name() not in defaults:
            held[u.name()] = (u, value)
    return held


__all__ = ["InitialDiscreteError", "at_initialisation", "solve_initial_discrete"]
