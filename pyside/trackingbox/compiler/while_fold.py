"""A ``while`` loop whose condition is symbolic, as one CasADi function of the loop's state applied
a fixed number of times (a part of :mod:`.while_loops`).

Unrolling such a loop adds its body to the expression graph once per pass: IF97's region-3
inverses (``Modelica.Media.Water.IF97_Utilities.dtofph3``, a Newton iteration bounded by
``IterationData.IMAX = 50``) grew to megabytes of generated C per call. Here the body is traced
once, on fresh symbols for the variables it assigns, into a function ``step`` of the loop's state
``s = (a, v, ok)``:

* ``a`` is 1 while the loop runs (``a_k = a_(k-1) and c_k``, ``c_k`` the condition at the start of
  pass *k*), ``v`` the values of the variables the body assigns, ``ok`` one flag per ``assert`` in
  the body (it stays 1 while every pass taken has met the assert);
* ``step(s) = if a and c(v) then (1, body(v), ok and conds(v)) else (0, v, ok)``, the branch taken
  by CasADi's short-circuit ``if_else`` (a conditional call: once the loop has ended, a pass costs
  a copy, not a body).

``step`` is applied :data:`.while_loops.MAX_PASSES` times (:func:`.repeat.repeated`: the body once in the
generated C, and the passes after the loop ended skipped in blocks), which gives the environment where the loop
ended, ``e_j`` for the first *j* with ``c_j`` false, the same as the unrolled loop. Variables the
body only reads (the function's inputs, the model's symbols) are the function's parameters.

The trace is given up (the caller unrolls the loop as before) where the body does something a
function of the state cannot carry: a relation that generates events, a value that is not a
Real/Integer/Boolean scalar or array of them, an array that changes its size, or a construct that
needs a concrete value where the state is now symbolic (an array subscript by a loop counter).
"""
from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import casadi as ca
import numpy as np

from ..errors import CompileError, UnsupportedConstructError
from . import arrays as arr
from .flat_builtins import is_number, logical_and
from .flat_model import Assertion
from .repeat import repeated

if TYPE_CHECKING:  # pragma: no cover
    from .flat_model import Value

_NAMES = itertools.count(1)
log = logging.getLogger(__name__)


class _Unfoldable(Exception):
    """The body cannot be traced as a function of the loop's state."""


def _elements(value: Any) -> tuple[tuple[int, ...], list[Any]]:
    """(shape, scalar elements) of a state value: numbers and scalar MX, or arrays of them."""
    shape = arr.shape(value) if arr.is_array(value) else ()
    elems = list(np.asarray(value, dtype=object).flat) if shape else [value]
    for e in elems:
        if not (is_number(e) or (isinstance(e, ca.MX) and e.is_scalar())):
            raise _Unfoldable(f"a value of type {type(e).__name__}")
    return shape, elems


def _unpack(vec: ca.MX, offset: int, shape: tuple[int, ...]) -> Any:
    """The value of *shape* whose elements start at *offset* in *vec*."""
    if not shape:
        return vec[offset]
    out = arr.new(shape)
    for k, idx in enumerate(np.ndindex(*shape)):
        out[idx] = vec[offset + k]
    return out


_EVENT_LISTS = ("conditions", "samples", "whens", "updates")


def event_state(tr: Any) -> tuple[Any, ...]:
    """What a traced pass must leave as it found: the event lists' lengths and the frozen relations."""
    return tuple(len(getattr(tr.events, name)) for name in _EVENT_LISTS) + (len(tr._discrete_defs), dict(tr._frozen))


def _restored(tr: Any, saved: tuple[Any, ...]) -> bool:
    """Whether a pass changed what :func:`event_state` saved; what it added is taken out again."""
    changed = event_state(tr)[:-1] != saved[:-1] or tr._frozen.keys() != saved[-1].keys()
    for name, n in zip(_EVENT_LISTS, saved):
        del getattr(tr.events, name)[n:]
    del tr._discrete_defs[saved[len(_EVENT_LISTS)]:]
    tr._frozen.clear()
    tr._frozen.update(saved[-1])
    return changed


@dataclass
class _Trace:
    x: ca.MX  # (a, v)
    layout: list[tuple[str, tuple[int, ...], int]]  # key, shape, offset in x
    active: Any  # a and c(v)
    values: list[Any]  # the body's new v, scalar elements
    asserts: list[Assertion]


def _trace(tr: Any, condition: Callable[[dict], Any], stmts: list[Any], fname: str,
           env: dict[str, Value], keys: list[str], shapes: dict[str, tuple[int, ...]]) -> _Trace | set[str]:
    """One pass on fresh symbols for *keys*; the keys the body also assigns where that is more."""
    layout, offset = [], 1
    for key in keys:
        layout.append((key, shapes[key], offset))
        offset += int(np.prod(shapes[key])) if shapes[key] else 1
    x = ca.MX.sym(f"tbx_while{next(_NAMES)}", offset)
    traced = dict(env)
    for key, shape, off in layout:
        traced[key] = _unpack(x, off, shape)
    n_asserts, events = len(tr.asserts), event_state(tr)
    body = dict(traced)
    try:
        active = logical_and(x[0], condition(traced))
        tr._statements(stmts, body, fname)
    except (UnsupportedConstructError, CompileError, RuntimeError) as exc:
        raise _Unfoldable(str(exc)) from exc
    finally:
        asserts = tr.asserts[n_asserts:]
        del tr.asserts[n_asserts:]
        if _restored(tr, events):
            raise _Unfoldable("a relation that generates events")
    more = {k for k, v in body.items() if k not in keys and (k not in traced or v is not traced[k])}
    for k in more:
        shapes[k] = _elements(body[k])[0]
    if more:
        return more
    values: list[Any] = []
    for key, shape, _ in layout:
        got, elems = _elements(body[key])
        if got != shape:
            raise _Unfoldable(f"{key!r} changes its size from {shape} to {got}")
        values += elems
    return _Trace(x, layout, active, values, asserts)


def _mx(v: Any) -> ca.MX:
    return ca.MX(float(v)) if is_number(v) else v


def folded_while(tr: Any, condition: Callable[[dict], Any], stmts: list[Any], fname: str,
                 env: dict[str, Value], passes: int) -> tuple[dict[str, Value], Any] | None:
    """The environment after at most *passes* passes of the loop from *env* (see the module's
    docstring), and the condition that it would still be running after them; None where the body
    cannot be traced as a function of its state (the caller unrolls it)."""
    probe = dict(env)
    n_asserts, events = len(tr.asserts), event_state(tr)
    try:  # which variables the body assigns, from a pass on the values as they stand
        tr._statements(stmts, probe, fname)
    except (UnsupportedConstructError, CompileError, RuntimeError):
        probe = None
    finally:
        del tr.asserts[n_asserts:]
        changed = _restored(tr, events)
    if probe is None or changed:
        log.debug("%s: a while loop in %s unrolled, not folded: its first pass %s", tr.model, fname,
                  "generates events" if changed else "fails")
        return None
    keys = [k for k, v in probe.items() if k not in env or v is not env[k]]
    try:
        shapes = {k: _elements(probe[k])[0] for k in keys}
        for _ in range(5):
            got = _trace(tr, condition, stmts, fname, env, keys, shapes)
            if isinstance(got, _Trace):
                break
            keys += sorted(got)
        else:
            return None
    except _Unfoldable as exc:
        log.debug("%s: a while loop in %s unrolled, not folded: %s", tr.model, fname, exc)
        return None
    log.debug("%s: a while loop in %s folded over %d passes (%d variables, %d asserts)", tr.model, fname,
              passes, got.x.numel() - 1, len(got.asserts))
    return _apply(tr, condition, env, got, passes)


def _apply(tr: Any, condition: Callable[[dict], Any], env: dict[str, Value], t: _Trace,
           passes: int) -> tuple[dict[str, Value], Any]:
    """The fold of the traced step over *passes* passes from *env*."""
    ok = ca.MX.sym(t.x.name() + "_ok", len(t.asserts))
    n = t.x.numel()
    running = ca.vertcat(1.0, *[_mx(v) for v in t.values],
                         *[ca.logic_and(ok[j], a.condition) for j, a in enumerate(t.asserts)])
    ended = ca.vertcat(0.0, t.x[1:n], ok)
    if is_number(t.active):
        out = running if bool(t.active) else ended
    else:
        out = ca.if_else(t.active, running, ended, True)
    own = {t.x.name()} | ({ok.name()} if t.asserts else set())  # (an empty symbol is a constant)
    params = [s for s in ca.symvar(ca.vertcat(out, ca.vertcat(*[_mx(v) for v in [t.active]])))
              if s.name() not in own]
    p = ca.veccat(*params) if params else ca.MX.sym(t.x.name() + "_p", 0)
    step = ca.Function(t.x.name() + "_step", [ca.vertcat(t.x, ok), p], [out], {"allow_free": False})
    start = [1.0]
    for key, shape, _ in t.layout:
        start += [_mx(e) for e in _elements(env[key])[1]] if key in env else [0.0] * (int(np.prod(shape)) if shape else 1)
    # (a pass from a = 0 returns its state: the passes after the loop ended are skipped in blocks)
    final = repeated(step, passes, lambda s: s[0] == 0, t.x.name())(
        ca.vertcat(*[_mx(v) for v in start], ca.DM.ones(len(t.asserts))), p)
    result = dict(env)
    for key, shape, off in t.layout:
        result[key] = _unpack(final, off, shape)
    for j, a in enumerate(t.asserts):
        tr.asserts.append(Assertion(condition=ca.if_else(final[n + j], 1.0, 0.0), message=a.message,
                                    level=a.level, origin=a.origin))
    return result, logical_and(final[0], condition(result))
