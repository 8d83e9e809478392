"""An if-statement of a function whose branches reach a ``while`` loop, as one CasADi switch that
evaluates the branch taken only (a part of :class:`.flat_statements.StatementTranslation`).

The translator runs every branch of an if-statement on a copy of the environment and merges the
copies with ``if_else(c, a, b)``, which evaluates both ``a`` and ``b``. For IF97's
``waterBaseProp_ph`` (MSL 4.0.0, ``Modelica.Media.Water.IF97_Utilities``) that meant the region-3
branch, a call of the Newton iteration ``dtofph3`` (a folded ``while`` loop, :mod:`.while_fold`), ran at
every evaluation whatever the region: ``Fluid.Examples.Explanatory.MeasuringTemperature`` spent most of
its simulation there.

:func:`switched_if` traces each branch once on fresh symbols for the environment's values (numbers stay
numbers: an Integer flag still chooses its branches while translating) into a CasADi function of them,
and joins the functions with ``Function.conditional``: a call evaluates the function of the first branch
whose condition holds, and no other. What the branches assign are the switch's outputs; so are the asserts
a branch records (1 where it holds; the branches not taken give 1), which are recorded at the call with
the guards around the if-statement: an assert in a branch not taken does not fire. A variable that a
branch leaves undefined (not assigned before the if-statement nor in that branch) is NaN on that path,
as :data:`.flat_statements.UNDEFINED_FIELD`.

Only if-statements of functions (not algorithm sections, whose relations generate events) with a branch
that reaches a ``while`` loop, itself or through a function it calls, are switched: a switch costs a
function call, and a small branch is cheaper evaluated than called. Where a branch does what a function of
its environment cannot carry (an event, a String or record value, a construct that needs a constant where
the symbols now are), the if-statement is merged as before.
"""
from __future__ import annotations

import logging
from typing import Any

import casadi as ca
import numpy as np

from ..errors import CompileError, UnsupportedConstructError
from . import arrays as arr
from .flat_builtins import is_number
from .flat_model import Value, merged_asserts
from .while_calls import DERIVATIVE_OPTIONS, _flat, _loops, _walk_loops, unflatten
from .while_fold import _NAMES, _restored, event_state

log = logging.getLogger(__name__)


class _NotSwitched(Exception):
    """The branches cannot be one switch (the if-statement is merged as before)."""


def costly(tr: Any, stmts: list[Any]) -> bool:
    """Whether *stmts* reach a ``while`` loop, themselves or through a function they call (memoised per
    statement list on *tr*: a function's if-statements are translated at each of its traces)."""
    memo: dict[int, tuple[list[Any], bool]] = tr.__dict__.setdefault("_costly_branches", {})
    hit = memo.get(id(stmts))
    if hit is not None and hit[0] is stmts:
        return hit[1]
    calls: set[str] = set()
    found = _walk_loops(stmts, calls) or any(c in tr.functions and _loops(tr, c) for c in sorted(calls))
    memo[id(stmts)] = (stmts, found)
    return found


def _symbolic_inputs(env: dict[str, Value]) -> tuple[ca.MX, list[Any], dict[str, Value]]:
    """(x, the values x stands for, the environment on x): every CasADi element of *env* is an element of
    a fresh symbol *x*; numbers and what is not a number or an array of them stay as they are."""
    slots: list[tuple[str, tuple[int, ...], list[Any]]] = []
    actual: list[Any] = []
    for key, value in env.items():
        got = _flat(value)
        if got is None or all(is_number(e) for e in got[1]):
            continue
        slots.append((key, got[0], got[1]))
        actual += [e for e in got[1] if not is_number(e)]
    x = ca.MX.sym(f"tbx_if{next(_NAMES)}", len(actual))
    on_x = dict(env)
    at = 0
    for key, shape, elems in slots:
        new = []
        for e in elems:
            if is_number(e):
                new.append(e)
            else:
                new.append(x[at])
                at += 1
        if shape:
            v = arr.new(shape)
            for idx, e in zip(np.ndindex(*shape), new):
                v[idx] = e
            on_x[key] = v
        else:
            on_x[key] = new[0]
    return x, actual, on_x


def _branch_values(key: str, envs: list[dict[str, Value]], before: dict[str, Value]) -> list[tuple[tuple[int, ...], list[Any]]]:
    """The (shape, elements) of *key* after each branch; NaN where a branch leaves it undefined."""
    got = []
    for e in envs:
        value = e.get(key, before.get(key))
        got.append(None if value is None else _flat(value))
        if value is not None and got[-1] is None:
            raise _NotSwitched(f"{key!r} is not a number or an array of numbers")
    shapes = {g[0] for g in got if g is not None}
    if len(shapes) != 1:
        raise _NotSwitched(f"{key!r} has different sizes in the branches")
    shape = shapes.pop()
    n = int(np.prod(shape)) if shape else 1
    return [g if g is not None else (shape, [float("nan")] * n) for g in got]


def _mx(v: Any) -> ca.MX:
    return ca.MX(float(v)) if is_number(v) else v


def switched_if(tr: Any, chain: list[tuple[Any, list[Any]]], env: dict[str, Value], fname: str) -> bool:
    """Translate the if-statement *chain* (``(condition, statements)`` per branch that may be taken, the
    last one the else, condition None) as one switch on *env*; False where it is not (see the module's
    docstring), *env* then unchanged."""
    if len(chain) < 2 or not any(costly(tr, stmts) for _, stmts in chain):
        return False
    x, actual, on_x = _symbolic_inputs(env)
    guards, tr._guards = tr._guards, []
    n_asserts, events = len(tr.asserts), event_state(tr)
    envs, asserts = [], []
    try:
        for _, stmts in chain:
            branch = dict(on_x)
            start = len(tr.asserts)
            tr._statements(stmts, branch, fname)
            envs.append(branch)
            asserts.append(merged_asserts(tr.asserts[start:]))
    except (UnsupportedConstructError, CompileError, RuntimeError) as exc:
        log.debug("%s: an if-statement in %s merged, not switched: %s", tr.model, fname, exc)
        envs = []
    finally:
        tr._guards = guards
        del tr.asserts[n_asserts:]
        changed = _restored(tr, events)
    if not envs or changed:
        return False
    keys = sorted({k for e in envs for k, v in e.items() if k not in on_x or v is not on_x[k]})
    try:
        values = {k: _branch_values(k, envs, on_x) for k in keys}
    except _NotSwitched as exc:
        log.debug("%s: an if-statement in %s merged, not switched: %s", tr.model, fname, exc)
        return False
    kept = {k: v[0][1] for k, v in values.items() if all(b[0] == () and is_number(b[1][0]) for b in v)
            and len({(type(b[1][0]), b[1][0]) for b in v}) == 1}  # the same number on every path
    switched = [k for k in keys if k not in kept]
    n_slots = sum(len(a) for a in asserts)
    outs = []
    for j, branch_asserts in enumerate(asserts):
        elems = [_mx(e) for k in switched for e in values[k][j][1]]
        for i, other in enumerate(asserts):
            elems += [a.condition if i == j else ca.MX(1.0) for a in (branch_asserts if i == j else other)]
        outs.append(ca.vertcat(*elems) if elems else ca.MX(0, 1))
    params = [s for s in ca.symvar(ca.vertcat(*outs)) if s.name() != x.name()]
    p = ca.veccat(*params) if params else ca.MX(0, 1)
    name = x.name()
    fs = [ca.Function(f"{name}_branch{j}", [x, p], [o], DERIVATIVE_OPTIONS) for j, o in enumerate(outs)]
    switch = ca.Function.conditional(f"{name}_switch", fs[:-1], fs[-1], DERIVATIVE_OPTIONS)
    index: Any = ca.MX(float(len(chain) - 1))
    for j in reversed(range(len(chain) - 1)):
        index = ca.if_else(chain[j][0], float(j), index)
    res = switch(index, ca.vertcat(*[_mx(a) for a in actual]) if actual else ca.MX(0, 1), p)
    at = 0
    for k in keys:
        if k in kept:
            env[k] = kept[k][0]
            continue
        env[k], at = unflatten(res, at, values[k][0][0])
    for branch_asserts in asserts:
        for a in branch_asserts:
            tr._record_assert(res[at], a.message, a.level, a.origin)
            at += 1
    log.debug("%s: an if-statement of %d branches in %s switched (%d inputs, %d outputs, %d asserts)",
              tr.model, len(chain), fname, x.numel(), res.numel(), n_slots)
    return True
