"""Calls of functions with ``while`` loops, as calls of one CasADi function per Modelica function.

The translator inlines a Modelica function at each call. For a function that runs a ``while`` loop,
itself or through the functions it calls (``Modelica.Media.Water.IF97_Utilities.T_ph`` reaches the
region-3 inverse ``dtofph3``, a Newton iteration), every call would trace the loop and everything
around it again: a Fluid model with water in a few vessels and pipes calls such functions from dozens
of places, and was still translating after 15 minutes. :func:`called` traces such a function once per
combination of constant arguments (Integer flags such as IF97's ``phase`` and ``region`` stay
constants, so their branches are still chosen while translating) on fresh symbols for the others,
and gives each later call a call of that CasADi function: the expression graph and the generated C
hold the function once.

The function's asserts come out as extra outputs (1 where the assert holds) and are recorded at
each call with the guards of that call. A function is inlined as before where its trace does what a
CasADi function cannot carry: a record or String argument or result, or an event.
"""
from __future__ import annotations

import json
import logging
from typing import Any

import casadi as ca
import numpy as np

from ..errors import CompileError, UnsupportedConstructError
from . import arrays as arr
from .flat_builtins import is_number
from .flat_model import Value, merged_asserts
from .while_fold import _NAMES, _restored, event_state

log = logging.getLogger(__name__)

_MARKED = "_while_line_"

MIN_TRACED_SIZE = 5_000
"""A function whose :func:`inlined_size` reaches this is traced once per pattern of constant arguments,
like a function running a while loop, instead of being inlined at each call."""

MAX_TRACED_SIZE = 3_000_000
"""The largest :func:`traced_size` of a function that is traced; a larger one is refused. Before large
functions were traced apart, the same number bounded the whole inlined size of a function running a
while loop, measured (MSL 4.0.0): ``dofpt3`` 61 946 (traced in under a second),
``IF97_Utilities.h_pT`` 2 369 308 (4 s); ``IF97_Utilities.rho_ph`` inlined to 74 018 804 and took 130 s to
trace on a loaded machine. Traced apart, its callees count one node per call, and it compiles."""


DERIVATIVE_OPTIONS = {"max_num_dir": 1}
"""CasADi options of a traced function: derivatives in several directions are taken one direction at a
time (a loop over the one-direction derivative) instead of CasADi emitting one more copy of the function
per number of directions: ``Fluid.Examples.Explanatory.MeasuringTemperature`` gave 72 MB of C, 34 MB of it
copies such as ``fwd3_fwd1_fwd1_*`` (the Jacobian of a Newton solve, three directions, of the second
derivatives of the IF97 functions). (Central differences for the derivatives of order two and more
would have cut further, but CasADi 3.8.2 fails taking the adjoint of such a derivative, "Duplicate IO
name: fwd_i0", which its FMU export does.)"""


def _walk_loops(node: Any, calls: set[str]) -> bool:
    """Whether *node* (a part of rumoca's JSON) holds a ``while`` loop; the functions it calls into *calls*."""
    found = False
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, dict):
            if "While" in n:
                found = True
            fc = n.get("FunctionCall")
            if isinstance(fc, dict):
                name = (fc.get("name") or fc.get("comp") or {}).get("name") if isinstance(
                    fc.get("name") or fc.get("comp"), dict) else None
                if isinstance(name, str):
                    calls.add(name)
            text = n.get("text")
            if isinstance(text, str) and text.startswith(_MARKED):
                found = True
            stack.extend(n.values())
        elif isinstance(n, list):
            stack.extend(n)
    return found


def _loops(tr: Any, fname: str) -> bool:
    """Whether *fname* runs a ``while`` loop, itself or through a function it calls (memoised on *tr*)."""
    memo: dict[str, bool] = tr.__dict__.setdefault("_while_functions", {})
    if fname in memo:
        return memo[fname]
    memo[fname] = False  # (a recursive call is refused elsewhere)
    fn = tr.functions.get(fname)
    if fn is None or fn.get("external"):
        return False
    calls: set[str] = set()
    found = _walk_loops(fn, calls)
    for c in sorted(calls):
        if found:
            break
        found = c in tr.functions and _loops(tr, c)
    memo[fname] = found
    return found


def _calls_in(node: Any) -> tuple[int, list[str]]:
    """(number of JSON nodes, names of the functions called, once per call site) of *node*."""
    count, names, stack = 0, [], [node]
    while stack:
        n = stack.pop()
        count += 1
        if isinstance(n, dict):
            fc = n.get("FunctionCall")
            if isinstance(fc, dict):
                ref = fc.get("name") or fc.get("comp")
                if isinstance(ref, dict) and isinstance(ref.get("name"), str):
                    names.append(ref["name"])
            stack.extend(n.values())
        elif isinstance(n, list):
            stack.extend(n)
    return count, names


def inlined_size(tr: Any, fname: str) -> int:
    """The size of *fname* once every function it calls is inlined: its own JSON nodes plus, per call
    site, the inlined size of the function called (memoised on *tr*; external functions count 1)."""
    memo: dict[str, int] = tr.__dict__.setdefault("_while_sizes", {})
    if fname in memo:
        return memo[fname]
    memo[fname] = 1  # (a recursive call is refused elsewhere)
    fn = tr.functions.get(fname)
    if fn is None or fn.get("external"):
        return 1
    own, names = _calls_in(fn)
    memo[fname] = own + sum(inlined_size(tr, c) for c in names if c in tr.functions)
    return memo[fname]


def _flat(value: Any) -> tuple[tuple[int, ...], list[Any]] | None:
    """(shape, scalar elements) of a number, scalar MX or array of them; None for anything else."""
    if isinstance(value, (str, bytes)):
        return None
    shape = arr.shape(value) if arr.is_array(value) else ()
    elems = list(np.asarray(value, dtype=object).flat) if shape else [value]
    if all(is_number(e) or (isinstance(e, ca.MX) and e.is_scalar()) for e in elems):
        return shape, elems
    return None


def _constant(elems: list[Any]) -> bool:
    """Whether an argument stays a constant in the trace: Integer and Boolean values (flags such as IF97's
    ``phase`` and ``region`` choose branches); a Real, even a literal, is an input of the function, so
    that the calls with different pressures share one trace."""
    return all(isinstance(e, (bool, int, np.bool_, np.integer)) for e in elems)


def unflatten(res: ca.MX, at: int, shape: tuple[int, ...]) -> tuple[Value, int]:
    """The value of *shape* (a scalar where it is empty) read from the flat vector *res* from element *at* on,
    in the order ``np.ndindex`` gives; and where the next value starts."""
    if not shape:
        return res[at], at + 1
    v = arr.new(shape)
    for idx in np.ndindex(*shape):
        v[idx] = res[at]
        at += 1
    return v, at


def _trace(tr: Any, fname: str, fn: dict[str, Any], args: list[Value], key: tuple) -> Any:
    """(CasADi function, output layout, asserts, parameter symbols) of *fname* for the arguments'
    pattern *key*; None where it cannot be one."""
    inputs, sym_args = [], []
    for a in args:
        shape, elems = _flat(a)
        if _constant(elems):
            sym_args.append(a)
            continue
        s = ca.MX.sym(f"tbx_call{next(_NAMES)}", len(elems))  # (names unique: a nested trace's are its own)
        inputs.append(s)
        if shape:
            v = arr.new(shape)
            for j, idx in enumerate(np.ndindex(*shape)):
                v[idx] = s[j]
            sym_args.append(v)
        else:
            sym_args.append(s[0])
    tracing: set = tr.__dict__.setdefault("_while_tracing", set())
    guards, tr._guards = tr._guards, []
    n_asserts, events = len(tr.asserts), event_state(tr)
    tracing.add(key)
    try:
        outs = tr.inline(fname, fn, sym_args)
    except (UnsupportedConstructError, CompileError):
        outs = None  # (e.g. a Real input that must be a constant there: inlined at the call instead)
    finally:
        tracing.discard(key)
        tr._guards = guards
        asserts = tr.asserts[n_asserts:]
        del tr.asserts[n_asserts:]
        changed = _restored(tr, events)
    if changed or outs is None:
        return None  # (inlined at the call instead, which records its events there)
    layout, values = [], []
    for o in outs:
        got = _flat(o)
        if got is None:
            return None
        layout.append(got[0])
        values += [ca.MX(float(e)) if is_number(e) else e for e in got[1]]
    asserts = merged_asserts(asserts)
    values += [a.condition for a in asserts]
    out = ca.vertcat(*values) if values else ca.MX(0, 1)
    own = {s.name() for s in inputs}
    params = [s for s in ca.symvar(out) if s.name() not in own]
    p = ca.veccat(*params) if params else ca.MX(0, 1)
    f = ca.Function(f"tbx_fn{next(_NAMES)}", [*inputs, p], [out], DERIVATIVE_OPTIONS)
    return f, layout, asserts, p


def _traced(tr: Any, fname: str) -> bool:
    """Whether a call of *fname* with symbolic arguments is traced once (it runs a while loop, or it inlines
    to :data:`MIN_TRACED_SIZE` nodes or more) rather than inlined."""
    return _loops(tr, fname) or inlined_size(tr, fname) >= MIN_TRACED_SIZE


def traced_size(tr: Any, fname: str) -> int:
    """The size of *fname*'s own trace: its JSON nodes plus, per call site, the inlined size of a function
    that is inlined there, or 1 for a call of a traced function (a call node: its body is traced apart)."""
    fn = tr.functions.get(fname)
    if fn is None or fn.get("external"):
        return 1
    own, names = _calls_in(fn)
    return own + sum(1 if _traced(tr, c) else inlined_size(tr, c) for c in names if c in tr.functions)


_NOT_THE_DEFINITION = ("name", "instance_id")
"""Fields of rumoca's function JSON that differ between two names of one definition."""


def same_as(tr: Any, fname: str, fn: dict[str, Any]) -> str:
    """The first function name under which the front end gave *fn*'s definition: rumoca 0.10.2 gives a
    function called through a package's short name (``density_ph`` in a medium's own functions) apart from
    the same function by its full name (``Modelica.Media.Water.WaterIF97_ph.density_ph``), and each was
    traced, with everything it calls, into the FMU's C. Definitions that are equal but for their name are
    one function: their calls name the same functions and they compute the same (the translator reads a
function's name only for its messages)."""
    memo: dict[str, str] = tr.__dict__.setdefault("_while_same", {})
    if fname not in memo:
        text = json.dumps({k: v for k, v in fn.items() if k not in _NOT_THE_DEFINITION}, sort_keys=True, default=repr)
        memo[fname] = tr.__dict__.setdefault("_while_bodies", {}).setdefault(text, fname)
        if memo[fname] != fname:
            log.debug("%s: %s is %s by its definition: traced once for both", tr.model, fname, memo[fname])
    return memo[fname]


def called(tr: Any, fname: str, fn: dict[str, Any], args: list[Value]) -> list[Value] | None:
    """The outputs of ``fname(args)`` as a call of its traced CasADi function (see the module's
    docstring); None where the function is to be inlined as before (neither a ``while`` loop reached nor
    a large body, every argument a constant, or a trace that cannot be a function)."""
    if not _traced(tr, fname):
        return None
    flats = [_flat(a) for a in args]
    if any(f is None for f in flats) or all(is_number(e) for f in flats for e in f[1]):
        return None
    key = (same_as(tr, fname, fn),) + tuple(("c", tuple(f[1]), f[0]) if _constant(f[1]) else ("s", f[0]) for f in flats)
    if key in tr.__dict__.setdefault("_while_tracing", set()):
        return None  # the trace itself
    cache: dict[tuple, Any] = tr.__dict__.setdefault("_while_calls", {})
    if key not in cache:
        size = traced_size(tr, fname)
        if size > MAX_TRACED_SIZE:
            raise tr.unsupported(f"call of function {fname!r}, whose trace (its body with the small functions it "
                                 f"calls inlined) counts {size} nodes (the embedded backend traces a function "
                                 f"up to {MAX_TRACED_SIZE})")
        cache[key] = _trace(tr, fname, fn, args, key)
        log.debug("%s: %s %s", tr.model, fname, f"traced once as a CasADi function of {cache[key][0].n_nodes()} "
                  "nodes" if cache[key] is not None else "inlined at each call (its trace cannot be a function)")
    traced = cache[key]
    if traced is None:
        return None
    f, layout, asserts, p = traced
    actual = [ca.vertcat(*[ca.MX(float(e)) if is_number(e) else e for e in fl[1]])
              for fl in flats if not _constant(fl[1])]
    res = f(*actual, p)
    outs: list[Value] = []
    at = 0
    for shape in layout:
        v, at = unflatten(res, at, shape)
        outs.append(v)
    for a in asserts:
        tr._record_assert(res[at], a.message, a.level, a.origin)
        at += 1
    return outs
