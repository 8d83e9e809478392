"""``while`` statements in functions and algorithm sections, executed symbolically (a part of
:class:`.flat_statements.StatementTranslation`).

The loop runs on the executor's environment of CasADi values, as an if-statement does. Pass *k*
starts from ``e_k`` (the environment after the body ran *k* times, ``e_0`` the one before the loop)
and the condition ``c_k`` is evaluated there. The loop is still running at pass *k* where
``a_k = c_0 and ... and c_k`` holds; on that path the environment is exactly ``e_k`` (every earlier
pass ran), so the result is ``e_j`` for the first *j* with ``c_j`` false, built forwards as
``r := if a_k then e_(k+1) else r``. Asserts in the body count only where ``a_k`` holds.

* Where ``c_k`` is a constant (a counter compared with a bound, ``found`` still false before the
  first pass) the pass is taken or the loop ends without any symbolic guard: a loop whose
  condition is constant runs concretely, and a loop such as IF97's
  ``while i < IterationData.IMAX and not found`` (``i`` incremented on every pass) ends after exactly
  ``IMAX`` passes, the bound proved by the condition itself.
* A loop whose condition stays symbolic is unrolled to :data:`MAX_PASSES` passes; where it would
  still be running after them, the model stops with an error naming the loop's file and line
  (an assert, never a silently wrong value).
* A loop whose condition stays the constant ``true`` for :data:`MAX_CONSTANT_PASSES` passes does
  not end: refused at compile time, naming the loop.

Each pass adds the body's expression once (and once more to the derivatives the integrator needs),
so an unrolled loop of *n* passes costs *n* bodies in the CasADi graph and in the generated C.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import re

import casadi as ca

from ..errors import UnsupportedConstructError
from . import arrays as arr
from .flat_builtins import is_number, logical_and, logical_not
from .source import Location
from .while_fold import folded_while

if TYPE_CHECKING:  # pragma: no cover
    from .flat_model import Value

MAX_PASSES = 100
"""Passes a loop with a symbolic condition is unrolled to before its end is asserted."""

MAX_CONSTANT_PASSES = 10_000
"""Passes a loop whose condition is a constant may take before it is refused as not ending."""

RETURNED = "\0returned"  # (flat_statements._RETURNED: where a return statement was taken)


def _merge(active: Any, new: dict[str, Value], old: dict[str, Value]) -> dict[str, Value]:
    """``if active then new else old`` key by key (a key in one of them only keeps that value)."""
    if is_number(active):
        return new if bool(active) else old
    out: dict[str, Value] = {}
    for key in set(new) | set(old):
        a, b = new.get(key), old.get(key)
        if a is None or b is None:
            out[key] = a if b is None else b
        elif a is b or (is_number(a) and is_number(b) and a == b and type(a) is type(b)):
            out[key] = a
        else:
            out[key] = arr.map2(lambda x, y: ca.if_else(active, x, y), a, b, f"while-loop passes of {key!r}")
    return out


def _refused(tr: Any, construct: str) -> UnsupportedConstructError:
    """The refusal of a loop, located by :func:`while_statement`'s own file and line (the translator's
    default span is an offset into the text rumoca read, which :mod:`.while_source` may have changed)."""
    return UnsupportedConstructError(f"unsupported Modelica construct in {tr.model}: {construct}. The embedded "
                                     "backend cannot compile it; use --backend openmodelica where omc is "
                                     "installed, or rewrite the model")


def _not_ended(where: str, named: str) -> str:
    return (f"the while loop{where} in {named} did not end within {MAX_PASSES} passes "
            "(the embedded compiler runs it that many)")


def while_statement(tr: Any, body: dict[str, Any], env: dict[str, Value], fname: str) -> None:
    """Execute ``while cond loop stmts end while`` on *env* (see the module's docstring)."""
    algorithm = fname.startswith(("algorithm ", "initial algorithm "))
    named = f"the {fname}" if algorithm else f"function {fname!r}"
    block = body.get("block") or body
    cond_node = block.get("cond")
    stmts = block.get("stmts") or block.get("body") or []
    span = cond_node.get(next(iter(cond_node)), {}).get("span") if isinstance(cond_node, dict) and cond_node else None
    where: str | None = None

    def place() -> str:
        nonlocal where
        if where is None:
            # the condition's file and line (a search for the keyword could name another loop of the file)
            locs = tr.location(None, span) if isinstance(span, dict) else []
            if locs and body.get("line"):  # (a for loop written from the while: the span's file, its line)
                locs = [Location(locs[0].file, int(body["line"]))]
            where = f" at {locs[0]}" if locs else ""
        return where

    def condition(e: dict[str, Value]) -> Any:
        saved, tr._freeze = tr._freeze, False  # relations in functions generate no events
        try:
            c = tr.expr(cond_node, e)
        finally:
            tr._freeze = saved
        if arr.is_array(c):
            raise _refused(tr, f"while statement{place()} in {named} whose condition is an array")
        returned = e.get(RETURNED, False)
        return logical_and(c, logical_not(returned)) if RETURNED in e else c

    current = dict(env)  # e_k
    result = env  # r: the environment where the loop has ended so far
    active: Any = True  # a_(k-1)
    symbolic_passes = constant_passes = 0
    while True:
        cond = condition(current)
        if symbolic_passes == 0 and is_number(active) and bool(active) and not is_number(cond):
            # the first pass whose condition is symbolic: the rest as one body folded (.while_fold)
            got = folded_while(tr, condition, stmts, fname, current, MAX_PASSES)
            if got is not None:
                result, running = got
                tr._record_assert(logical_not(running), _not_ended(place(), named), "error",
                                  fname if algorithm else f"function {fname}")
                break
        active = logical_and(active, cond)
        if is_number(active) and not bool(active):
            break  # the loop has ended on every path
        if is_number(active):
            constant_passes += 1
            if constant_passes > MAX_CONSTANT_PASSES:
                raise _refused(tr, f"while statement{place()} in {named} whose condition stays true: it has not "
                                   f"ended after {MAX_CONSTANT_PASSES} passes")
        else:
            symbolic_passes += 1
            if symbolic_passes > MAX_PASSES:
                tr._record_assert(logical_not(active), _not_ended(place(), named), "error",
                                  fname if algorithm else f"function {fname}")
                break
        following = dict(current)
        if not is_number(active):
            tr._guards.append(active)
        try:
            tr._statements(stmts, following, fname)
        finally:
            if not is_number(active):
                tr._guards.pop()
        result = _merge(active, following, result if result is not env else dict(env))
        current = following
    if result is not env:
        env.clear()
        env.update(result)


def marked_while(body: dict[str, Any]) -> dict[str, Any] | None:
    """The ``while`` statement a ``for`` loop was written from by :mod:`.while_source`
    (``for _while_line_L in 1:N loop if COND then BODY end if; end for``, L the while's line), as a while statement's
    body; None for any other ``for`` loop."""
    indices = body.get("indices") or []
    if len(indices) != 1:
        return None
    ident = indices[0].get("ident")
    name = str(ident.get("text") if isinstance(ident, dict) else ident)
    if not re.fullmatch(r"_while_line_\d+", name):
        return None
    stmts = body.get("equations") or body.get("stmts") or body.get("body") or []
    if len(stmts) != 1 or not isinstance(stmts[0], dict) or "If" not in stmts[0]:
        return None
    branch = stmts[0]["If"]
    blocks = branch.get("cond_blocks") or branch.get("branches") or []
    if len(blocks) != 1 or branch.get("else_block") or branch.get("else_branch") or not isinstance(blocks[0], dict):
        return None
    return {"block": {"cond": blocks[0].get("cond"), "stmts": blocks[0].get("stmts", blocks[0].get("body", []))},
            "line": int(name.rsplit("_", 1)[1])}
