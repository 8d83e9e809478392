"""Functions and algorithm sections executed symbolically (:class:`StatementTranslation`, a part
of :class:`.flatten.FlatTranslator`): a function call inlined into its outputs, assignments,
if-, for- and when-statements, ``return``, asserts, and an algorithm section as equations.
"""
from __future__ import annotations

import json
import re
from typing import Any

import casadi as ca
import numpy as np

from ..errors import CompileError
from . import arrays as arr
from . import lapack, random_ext, records
from .flat_model import STRING, Assertion, Value, kind_of
from .flat_builtins import builtin_call, builtin_external_name, if_then, is_number, logical_not
from .flat_text import literal_text
from .if_switch import switched_if
from .records import Record
from .while_calls import called, same_as
from .while_fold import event_state
from .while_loops import marked_while, while_statement

_RETURNED = "\0returned"  # in a function's environment: where a return statement was taken


def _branch_guard(cond: Any, prior: list[Any]) -> Any:
    """The condition under which an if-branch is taken: *cond* and none of the *prior* ones."""
    guard = None if cond is None else cond
    for p in prior:
        guard = logical_not(p) if guard is None else ca.logic_and(guard, logical_not(p))
    return guard


def _declared_dims(loc: dict[str, Any]) -> list[Any]:
    """The declared sizes of a function's input, output or local: ``dims`` where the flat model gives
    them so, else its ``shape_expr`` (rumoca 0.10.2: ``{"Index": {"value": n}}`` for a literal size,
    ``{"Expr": {"expr": e}}`` for an expression such as an input ``order``, anything else for ``:``)."""
    if loc.get("dims"):
        return list(loc["dims"])
    out: list[Any] = []
    for d in loc.get("shape_expr") or []:
        kind, body = kind_of(d)
        if kind == "Index" and isinstance(body, dict) and isinstance(body.get("value"), int):
            out.append(int(body["value"]))
        elif kind == "Expr" and isinstance(body, dict) and body.get("expr") is not None:
            out.append(body["expr"])
        else:
            out.append({"Colon": None})
    return out


# The value of a field of a function's record output that no statement on the path taken assigns
# (MSL 4.0.0's ``IF97_Utilities.BaseIF97.Regions.boilingcurve_p`` sets ``bpro.cv`` only near the
# critical point, ``bpro.cp`` only away from it): undefined in Modelica (MLS 12.4.4: a variable of a
# function without a binding is undefined until assigned), so any number computed from it is NaN,
# which stops the simulation, rather than a value.
UNDEFINED_FIELD = float("nan")


def _is_zero_literal(node: Any) -> bool:
    kind, body = kind_of(node)
    return kind == "Literal" and isinstance(body, dict) and kind_of(body.get("value"))[0] == "Real" \
        and kind_of(body.get("value"))[1] == 0.0


def _undefined_marker(node: Any) -> bool:
    """Whether *node* is ``0.0/0.0`` or ``integer(0.0/0.0)``, the binding :mod:`.function_locals` gives a
    function local that stands for "undefined" (MLS 12.4.4)."""
    kind, body = kind_of(node)
    if kind == "BuiltinCall" and isinstance(body, dict) and str(body.get("function")).lower() == "integer":
        args = body.get("args") or []
        return len(args) == 1 and _undefined_marker(args[0])
    return kind == "Binary" and isinstance(body, dict) and str(body.get("op")).lower() == "div" \
        and _is_zero_literal(body.get("lhs")) and _is_zero_literal(body.get("rhs"))


_NAN_LITERAL = {"Literal": {"value": {"Real": float("nan")}}}


def undefined_binding(node: Any) -> tuple[bool, Any]:
    """(whether the binding *node* of a function local holds the undefined marker, *node* with each
    marker replaced by a NaN literal: a record constructor's arguments each undefined)."""
    if _undefined_marker(node):
        return True, _NAN_LITERAL
    if isinstance(node, dict):
        found, out = False, {}
        for key, val in node.items():
            hit, out[key] = undefined_binding(val)
            found = found or hit
        return (True, out) if found else (False, node)
    if isinstance(node, list):
        pairs = [undefined_binding(v) for v in node]
        return (True, [v for _, v in pairs]) if any(h for h, _ in pairs) else (False, node)
    return False, node


def _assigned(node: Any, out: set[str]) -> set[str]:
    """The first names of the targets of the assignments in the statements *node*, nested ones too."""
    if isinstance(node, dict):
        for key, val in node.items():
            if key == "Assignment" and isinstance(val, dict):
                parts = (val.get("comp") or {}).get("parts") or []
                if parts:
                    out.add(parts[0].get("ident"))
            _assigned(val, out)
    elif isinstance(node, list):
        for item in node:
            _assigned(item, out)
    return out


def _record_field_locals(fn: dict[str, Any]) -> set[str]:
    """The locals rumoca 0.10.2 makes for the fields of *fn*'s record outputs (``bpro__cv`` for
    ``bpro.cv``, copied into the output after the body), scalar, without a binding, and assigned by
    some statement of the body (a field no statement assigns stays an error)."""
    prefixes = tuple(o["name"] + "__" for o in fn.get("outputs") or [] if o.get("type_class") == "Record")
    if not prefixes:
        return set()
    fields = {loc["name"] for loc in fn.get("locals") or [] if loc["name"].startswith(prefixes)
              and loc.get("default") is None and not _declared_dims(loc)}
    return fields & _assigned(fn.get("body") or [], set()) if fields else fields


def _numeric(value: Value) -> bool:
    """Whether *value* is a number or an array of numbers."""
    if isinstance(value, np.ndarray):
        return all(is_number(e) for e in value.flat)
    return is_number(value)


def _numeric_call_key(tr: Any, fname: str, fn: dict[str, Any], args: list[Value]) -> tuple | None:
    """The key under which a call of *fn* with these number arguments is evaluated once, or None (an
    argument that is not a number, an external or impure function)."""
    if fn.get("external") or fn.get("pure") is False or not all(_numeric(a) for a in args):
        return None
    frozen = tuple((a.shape, tuple((type(e).__name__, e) for e in a.flat)) if isinstance(a, np.ndarray)
                   else (type(a).__name__, a) for a in args)
    return (same_as(tr, fname, fn), frozen)


def _node_key(value: Any) -> Any:
    """A hashable key standing for *value* in :func:`_symbolic_call_key`: a CasADi MX by its node (the
    address CasADi hashes it by: the same node, not an equal expression built again), numbers and
    strings with their type, arrays and records element by element; None for anything else."""
    if isinstance(value, ca.MX):
        return ("MX", hash(value))
    if isinstance(value, (bool, int, float, str, np.bool_, np.integer, np.floating)):
        return (type(value).__name__, value)
    if isinstance(value, Record):
        fields = tuple((k, _node_key(v)) for k, v in value.items())
        return None if any(f[1] is None for f in fields) else ("Record", fields)
    if isinstance(value, np.ndarray):
        elems = tuple(_node_key(e) for e in value.flat)
        return None if any(e is None for e in elems) else ("array", value.shape, elems)
    return None


def _symbolic_call_key(tr: Any, fname: str, fn: dict[str, Any], args: list[Value]) -> tuple | None:
    """The key under which a call of *fn* with these arguments under the if-branch guards being inlined
    is built once (:meth:`StatementTranslation._shared_call`), or None (an external or impure function,
    an argument or guard :func:`_node_key` cannot stand for)."""
    if fn.get("external") or fn.get("pure") is False:
        return None
    parts = tuple(_node_key(a) for a in args) + ("guards",) + tuple(_node_key(g) for g in tr._guards)
    return None if any(p is None for p in parts) else (same_as(tr, fname, fn), parts)


def _ref_names(node: Any, out: set[str]) -> set[str]:
    """The first parts of the names the expression *node* reads (``state`` for ``state.p``)."""
    if isinstance(node, dict):
        ref = node.get("VarRef")
        if isinstance(ref, dict) and isinstance(ref.get("name"), dict) and isinstance(ref["name"].get("name"), str):
            out.add(ref["name"]["name"].split(".", 1)[0])
        for val in node.values():
            _ref_names(val, out)
    elif isinstance(node, list):
        for item in node:
            _ref_names(item, out)
    return out


def _call_read_key(tr: Any, node: Any, env: dict[str, Value]) -> tuple | None:
    """The key of :meth:`StatementTranslation.read_call`: the call's text, the if-branch guards being
    inlined, and each entry of *env* under a name the call reads (``state``, ``state.p``; a name not in
    *env* is a constant of the function's package, the same everywhere), by :func:`_node_key`; None
    where one of them has no such key."""
    texts: dict[int, tuple] = tr.__dict__.setdefault("_call_texts", {})
    got = texts.get(id(node))
    if got is None or got[0] is not node:  # (the node is kept with its text: its id stays its own)
        got = texts[id(node)] = (node, json.dumps(node, sort_keys=True, default=repr), _ref_names(node, set()))
    names = got[2]
    entries = tuple(sorted(k for k in env if isinstance(k, str) and k.split(".", 1)[0] in names))
    parts = tuple(_node_key(env[k]) for k in entries) + tuple(_node_key(g) for g in tr._guards)
    return None if any(p is None for p in parts) else (got[1], len(tr._guards), entries, parts)


def _copied(value: Value) -> Value:
    """*value* with its arrays and records copied (their elements, CasADi nodes or numbers, shared), so
    that a caller assigning into one leaves the shared call's outputs as they were."""
    if isinstance(value, Record):
        return Record((k, _copied(v)) for k, v in value.items())
    if isinstance(value, np.ndarray):
        if value.dtype != object:
            return value.copy()
        out = np.empty(value.shape, dtype=object)
        for idx in np.ndindex(*value.shape):
            out[idx] = _copied(value[idx])
        return out
    return value


def _var_name(node: Any) -> str | None:
    """The name an expression node refers to when it is a plain variable reference, else None."""
    kind, body = kind_of(node)
    if kind != "VarRef" or not isinstance(body, dict) or body.get("subscripts"):
        return None
    return (body.get("name") or {}).get("name")


def _is_algorithm(context: str) -> bool:
    """Whether a statement context names an algorithm section of the model (not a function)."""
    return context.startswith(("algorithm ", "initial algorithm "))


def _in(context: str) -> str:
    """``in function 'f'`` or ``in the initial algorithm of pipe`` for messages."""
    return f"in the {context}" if _is_algorithm(context) else f"in function {context!r}"


class StatementTranslation:
    """The statement part of :class:`.flatten.FlatTranslator` (its state is set up there)."""

    # ------------------------------------------------------------ functions
    def inline(self, fname: str, fn: dict[str, Any], args: list[Value]) -> list[Value]:
        """The outputs of ``fname(args)``. A call with numbers for every argument whose evaluation records no
        assert and no event is evaluated once per definition and arguments (a Modelica function's outputs
        depend on its inputs only, MLS 12.3): the IF97 start values of a model's media (``h_start`` from
        ``p_start`` and ``T_start``) were evaluated again for every component and every use."""
        key = _numeric_call_key(self, fname, fn, args)
        if key is None:
            return self._shared_call(fname, fn, args)
        memo: dict[tuple, list[Value]] = self.__dict__.setdefault("_numeric_calls", {})
        if key in memo:
            return [v.copy() if isinstance(v, np.ndarray) else v for v in memo[key]]
        n_asserts, before = len(self.asserts), event_state(self)
        outs = self._inline(fname, fn, args)
        after = event_state(self)
        if (len(self.asserts) == n_asserts and after[:-1] == before[:-1] and after[-1].keys() == before[-1].keys()
                and all(_numeric(v) for v in outs)):
            memo[key] = [v.copy() if isinstance(v, np.ndarray) else v for v in outs]
        return outs

    def _shared_call(self, fname: str, fn: dict[str, Any], args: list[Value]) -> list[Value]:
        """The outputs of ``fname(args)`` for symbolic arguments: a call with the same arguments (the same
        CasADi nodes, :func:`_symbolic_call_key`) under the same if-branch guards gives the outputs the first
        one built, so that the expression graph holds the call once. The asserts that call recorded are
        recorded again (as each inlined call records its own); a call that records an event is built at each
        call. IF97's ``g2(p, T).gpi`` beside ``g2(p, T).gtau`` inlined ``g2`` once per field, and so on down
        the calls it makes."""
        key = _symbolic_call_key(self, fname, fn, args)
        if key is None:
            return self._inline(fname, fn, args)
        memo: dict[tuple, tuple] = self.__dict__.setdefault("_symbolic_calls", {})
        hit = memo.get(key)
        if hit is not None:
            self.asserts.extend(hit[1])
            return [_copied(v) for v in hit[0]]
        n_asserts, before = len(self.asserts), event_state(self)
        outs = self._inline(fname, fn, args)
        after = event_state(self)
        if after[:-1] == before[:-1] and after[-1].keys() == before[-1].keys():
            # (the arguments and guards are kept with the entry: the key holds their nodes' addresses)
            memo[key] = ([_copied(v) for v in outs], self.asserts[n_asserts:], args, list(self._guards))
        return outs

    def read_call(self, node: Any, env: dict[str, Value] | None) -> Value:
        """The value of the call *node* a field is read of in a function's body (``f(x).p``): rumoca
        passes a record argument field by field, so ``g(f(x))`` reaches the translator as ``g(f(x).p,
        f(x).h, ...)``, each ``f(x)`` a copy of the whole call with its own arguments (themselves field
        reads of calls, and so on down). The call's value is kept per its text and the nodes the names it
        reads stand for (:func:`_call_read_key`), so each copy after the first costs no walk of its
        arguments: the walks multiplied by the number of fields at every level (``HeatingSystem``'s
        IF97 calls). The asserts it recorded are recorded again; one that records an event is read anew."""
        key = _call_read_key(self, node, env) if env is not None else None
        if key is None:
            return self.expr(node, env)
        memo: dict[tuple, tuple] = self.__dict__.setdefault("_call_reads", {})
        hit = memo.get(key)
        if hit is not None:
            self.asserts.extend(hit[1])
            return _copied(hit[0])
        n_asserts, before = len(self.asserts), event_state(self)
        value = self.expr(node, env)
        after = event_state(self)
        if after[:-1] == before[:-1] and after[-1].keys() == before[-1].keys():
            memo[key] = (_copied(value), self.asserts[n_asserts:], [env[k] for k in key[2]], list(self._guards))
        return value

    def _inline(self, fname: str, fn: dict[str, Any], args: list[Value]) -> list[Value]:
        ext = fn.get("external")
        builtin = builtin_external_name(ext) if ext else None
        if builtin is not None:  # external "builtin": the language's own function (Modelica.Math.sin, ...)
            return self._builtin_external(fname, fn, ext, builtin, args)
        vectorized = self._vectorized(fname, fn, args)
        if vectorized is not None:
            return vectorized
        if ext:
            return self._external(fname, fn, ext, args)
        traced = called(self, fname, fn, args)  # a function running a while loop: traced once (.while_calls)
        if traced is not None:
            return traced
        self._inline_depth += 1
        if self._inline_depth > 40:
            raise self.unsupported(f"recursive function {fname!r}")
        try:
            env = self._bind_inputs(fname, fn, args, f"call of {fname!r} in {self.model} lacks argument")
            unset_fields = self._unset_fields(fname, fn)
            for loc in (fn.get("outputs") or []) + (fn.get("locals") or []):
                if loc.get("default") is not None:
                    value = self.expr(undefined_binding(loc["default"])[1], env)
                    if isinstance(value, Record):
                        records.store(loc["name"], value, env)
                    else:
                        env[loc["name"]] = value
                elif _declared_dims(loc):  # an array declared with its sizes: its elements can be assigned
                    dims = self._local_dims(loc, env, fname)
                    if dims is not None:
                        env[loc["name"]] = arr.fill(0.0, list(dims))
                elif loc["name"] in unset_fields:
                    env[loc["name"]] = UNDEFINED_FIELD
            saved, self._freeze = self._freeze, False  # relations in functions generate no events
            env[_RETURNED] = False
            try:
                self._statements(fn.get("body") or [], env, fname)
            finally:
                self._freeze = saved
            outs = []
            for out in fn.get("outputs") or []:
                if out.get("type_class") == "Record" and out["name"] not in env:
                    outs.append(self._record_output(fname, fn, out, env))
                    continue
                if out["name"] not in env:
                    raise CompileError(f"function {fname!r} does not assign its output {out['name']!r}")
                outs.append(env[out["name"]])
            return outs
        finally:
            self._inline_depth -= 1

    def _unset_fields(self, fname: str, fn: dict[str, Any]) -> frozenset[str]:
        """:func:`_record_field_locals` of *fn*, once per function (it walks the whole body; an IF97
        function is inlined thousands of times in a ``Modelica.Fluid`` example)."""
        memo = self.__dict__.setdefault("_unset_fields_memo", {})
        found = memo.get(fname)
        if found is None or found[0] is not fn:
            found = memo[fname] = (fn, frozenset(_record_field_locals(fn)))
        return found[1]

    def _vectorized(self, fname: str, fn: dict[str, Any], args: list[Value]) -> list[Value] | None:
        """A call with arrays for scalar inputs (MLS 12.4.6): the function applied element by element,
        each result an array of that size; None when no scalar input has an array."""
        mapped = [arr.is_array(a) and not (inp.get("shape_expr") or (inp.get("effective_type") or {}).get("dimensions")
                                           or inp.get("type_class") == "Record")
                  for inp, a in zip(fn.get("inputs") or [], args)]
        shapes = {arr.shape(a) for a, m in zip(args, mapped) if m}
        if not shapes:
            return None
        if len(shapes) > 1:
            raise CompileError(f"vectorized call of {fname!r} in {self.model} with arrays of different sizes "
                               f"({', '.join(arr.size_text(s) for s in sorted(shapes))}) for scalar inputs")
        shape = shapes.pop()
        outs = [arr.new(shape) for _ in fn.get("outputs") or []]
        for idx in np.ndindex(*shape):
            results = self.inline(fname, fn, [a[idx] if m else a for a, m in zip(args, mapped)])
            for out, res in zip(outs, results):
                out[idx] = res
        return outs

    def _record_output(self, fname: str, fn: dict[str, Any], out: dict[str, Any], env: dict[str, Value]) -> Record:
        """A function's record output, from its fields in *env*; each field the record type declares
        must have been assigned."""
        value = records.gather(out["name"], env, env.__getitem__) or Record()
        declared = ((self.flat.get("record_types") or {}).get(str(out.get("type_def_id"))) or {}).get("fields") or []
        unset = [f["name"] for f in declared if f.get("name") not in value]
        if unset or not value:
            raise CompileError(f"function {fname!r} does not assign field{'s' if len(unset) > 1 else ''} "
                               f"{', '.join(unset) or '(any)'} of its record output {out['name']!r} in {self.model}")
        return value

    def record_constructor(self, fname: str, fn: dict[str, Any], args: list[Value]) -> Record:
        """``R(a, b)`` (the front end orders named arguments): the record of the given fields, the others
        at their declared defaults."""
        env = self._bind_inputs(fname, fn, args, f"record constructor {fname!r} in {self.model} lacks field")
        out = Record()
        for inp in fn.get("inputs") or []:
            out[inp["name"]] = env[inp["name"]]
        return out

    def _bind_inputs(self, fname: str, fn: dict[str, Any], args: list[Value], lacks: str) -> dict[str, Value]:
        """A call's inputs by position: the given arguments, then the inputs' defaults (which may read the
        inputs before them); an input with neither is refused as ``lacks 'name'``."""
        env: dict[str, Value] = {}
        for i, inp in enumerate(fn.get("inputs") or []):
            if i < len(args):
                env[inp["name"]] = args[i]
            elif inp.get("default") is not None:
                env[inp["name"]] = self.expr(inp["default"], env)
            else:
                raise CompileError(f"{lacks} {inp['name']!r}")
        return env

    def _local_dims(self, loc: dict[str, Any], env: dict[str, Value], fname: str) -> tuple[int, ...] | None:
        """The sizes of a function's local or output array (None when one is flexible, ``:``)."""
        out = []
        for d in _declared_dims(loc):
            if isinstance(d, int):
                out.append(d)
                continue
            if kind_of(d)[0] in ("Colon", "Empty") or d is None:
                return None
            val = self.expr(d, env)
            if not is_number(val):
                return None
            out.append(int(val))
        return tuple(out)

    def _builtin_external(self, fname: str, fn: dict[str, Any], ext: dict[str, Any], builtin: str,
                          args: list[Value]) -> list[Value]:
        """``external "builtin" y = sin(u)``: the built-in on the external call's arguments, which
        name the function's inputs (given, or their defaults)."""
        env = self._bind_inputs(fname, fn, args, f"call of {fname!r} in {self.model} lacks argument")
        call_args = [self.expr(a, env) for a in ext.get("args") or []]
        value = builtin_call(builtin, call_args, self)
        outs = [o["name"] for o in fn.get("outputs") or []]
        if len(outs) != 1 or (ext.get("output_name") not in (None, outs[0])):
            raise self.unsupported(f"external \"builtin\" function {fname!r} with other than one output "
                                   "returned by the call", r"\bexternal\b")
        return [value]

    def _external(self, fname: str, fn: dict[str, Any], ext: dict[str, Any], args: list[Value]) -> list[Value]:
        """A function whose external routine the embedded path knows (:mod:`.lapack`): the routine on
        its call's arguments, the values it writes to the function's outputs returned; any other
        routine is refused naming the function and where it is declared."""
        language = str(ext.get("language") or "C").upper()
        if language == "BUILTIN":  # a built-in the language does not have (flat_builtins.builtin_external_name)
            raise self.unsupported(f"external function {fname!r}", r"\bexternal\b")
        routine = str(ext.get("function_name") or fname.rsplit(".", 1)[-1])
        shown = fname.removesuffix("__tuple")  # (the copy taking every output, see rewrite.first_output_functions)
        where = rf"\bfunction\s+{re.escape(shown.rsplit('.', 1)[-1])}\b"
        impl = lapack.ROUTINES.get(routine.lower()) if language == "FORTRAN 77" else None
        if language == "C" and routine in random_ext.ROUTINES:  # (Modelica.Math.Random, hashString)
            impl = random_ext.ROUTINES[routine]
        elif impl is None or ext.get("output_name"):
            raise self.unsupported(f"external function {shown!r} (external {language!r} routine {routine!r})", where)
        env = self._bind_inputs(fname, fn, args, f"call of {fname!r} in {self.model} lacks argument")
        for out in fn.get("outputs") or []:
            if out.get("default") is not None:
                env[out["name"]] = self.expr(out["default"], env)
        outs = {o["name"] for o in fn.get("outputs") or []}
        values = []
        for node in ext.get("args") or []:  # an output without a default is only written (None here)
            name = _var_name(node)
            values.append(None if name in outs and name not in env else self.expr(node, env))
        try:
            written = impl(values)
        except (lapack.NotGiven, random_ext.NotGiven) as exc:
            kind = f"LAPACK {routine}" if language == "FORTRAN 77" else routine
            raise self.unsupported(f"external function {shown!r} ({kind})", where, str(exc)) from None
        if ext.get("output_name") and -1 in written:
            env[ext["output_name"]] = written[-1]
        for k, node in enumerate(ext.get("args") or []):
            name = _var_name(node)
            if name in outs:
                if k not in written:
                    raise self.unsupported(f"external function {shown!r} (LAPACK {routine})", where,
                                           f"its output {name!r} is not given for these arguments")
                env[name] = written[k]
        missing = [o["name"] for o in fn.get("outputs") or [] if o["name"] not in env]
        if missing:
            raise CompileError(f"external function {fname!r} does not give its output {missing[0]!r}")
        return [env[o["name"]] for o in fn.get("outputs") or []]

    def _statements(self, stmts: list[Any], env: dict[str, Value], fname: str) -> None:
        for st in stmts:
            if _RETURNED in env and is_number(env[_RETURNED]) and bool(env[_RETURNED]):
                return  # after a return taken on every path, nothing more happens
            kind, body = kind_of(st)
            if kind == "Assignment":
                value = self.expr(body["value"], env)
                self._assign(body["comp"]["parts"], value, env, fname)
            elif kind == "FunctionCall":  # (a, b, ...) := f(...), or a call of a function for nothing
                cname = (body.get("comp") or {}).get("name") or ""
                args = [self.expr(a, env) for a in body.get("args") or []]
                fn = self.functions.get(cname)
                if fn is None:
                    raise CompileError(f"call of unknown function {cname!r} {_in(fname)} in {self.model}")
                outs = self.inline(cname, fn, args)
                targets = body.get("outputs") or []
                if len(targets) > len(outs):
                    raise CompileError(f"{len(targets)} results taken from {cname!r}, which has {len(outs)} "
                                       f"outputs, {_in(fname)}")
                for target, value in zip(targets, outs):
                    parts = (target or {}).get("parts") if isinstance(target, dict) else None
                    if parts:
                        self._assign(parts, value, env, fname)
            elif kind == "Return" and not _is_algorithm(fname):
                # in this branch's environment; merging the branches makes it the branch's condition
                env[_RETURNED] = True
            elif kind == "If":
                self._if_statement(body, env, fname)
            elif kind == "When" and _is_algorithm(fname):
                blocks = body.get("blocks") or []
                fires = [self.when_fire(blk.get("cond"), env) for blk in blocks]
                self._if_statement({"cond_blocks": [{"cond": None, "stmts": blk.get("stmts") or []} for blk in blocks],
                                    "else_block": []}, env, fname, conds=fires)
            elif kind == "For":
                self._for_statement(body, env, fname)
            elif kind == "While":
                while_statement(self, body, env, fname)
            elif kind == "Assert":
                self.add_assert(body, env, fname if _is_algorithm(fname) else f"function {fname}")
            else:
                pattern = {"Return": r"\breturn\b", "Break": r"\bbreak\b"}.get(kind)
                raise self.unsupported(f"{kind.lower()} statement {_in(fname)}", pattern)

    def _assign(self, parts: list[dict[str, Any]], value: Value, env: dict[str, Value], fname: str) -> None:
        """``target := value`` in a function or algorithm (a whole variable, array elements or slices);
        after a possible return, only where the function has not returned."""
        ident = self._flat_target(parts, env)
        subs = parts[-1].get("subs") or []
        if isinstance(value, Record):  # a record, field by field (records.store)
            if subs:
                raise self.unsupported(f"assignment of a record to an element of {ident!r} {_in(fname)}")
            fields: dict[str, Value] = {}
            records.store(ident, value, fields)
            for key, val in fields.items():
                self._assign([{"ident": key, "subs": []}], val, env, fname)
            return
        returned = env.get(_RETURNED, False)
        if subs:
            target = env.get(ident)
            if not isinstance(target, np.ndarray):
                raise self.unsupported(f"indexed assignment to {ident!r} {_in(fname)}")
            picks = [self._subscript(sb, target, k, env) for k, sb in enumerate(subs)]
            if len(picks) != target.ndim:
                raise CompileError(f"assignment to {ident!r} {_in(fname)} with {len(picks)} "
                                   f"subscripts for an array of size {arr.size_text(target.shape)}")
            index = tuple(
                slice(None) if p is None else ([int(i) - 1 for i in p] if arr.is_array(p) else int(p) - 1)
                for p in picks
            )
            for k, p in enumerate(picks):
                bad = [int(i) for i in (p if arr.is_array(p) else [p]) if p is not None
                       and not 1 <= int(i) <= target.shape[k]]
                if bad:
                    raise CompileError(f"index {bad[0]} out of range 1..{target.shape[k]} in assignment "
                                       f"to {ident!r} {_in(fname)}")
            new = target.copy()
            try:
                new[np.ix_(*[range(new.shape[k]) if p is None else
                             ([i] if isinstance(i, int) else i) for k, (p, i) in
                             enumerate(zip(picks, index))])] = (
                    np.asarray(value, dtype=object).reshape(
                        [new.shape[k] if p is None else (len(i) if isinstance(i, list) else 1)
                         for k, (p, i) in enumerate(zip(picks, index))])
                    if arr.is_array(value) else value)
            except ValueError:
                raise CompileError(f"assignment of a value of size {arr.size_text(arr.shape(value))} "
                                   f"to a part of {ident!r} {_in(fname)} that does not "
                                   "have that size") from None
            value = new
            old = target
        else:
            old = env.get(ident)
        if not (is_number(returned) and not bool(returned)) and old is not None:
            value = arr.map2(lambda a, b: if_then(returned, a, b), old, value, f"assignment to {ident!r}",
                             broadcast=False)
        env[ident] = value

    def _flat_target(self, parts: list[dict[str, Any]], env: dict[str, Value]) -> str:
        """The name an assignment's target ``a[2].b.c[i]`` has in the environment: the flat name
        ``a[2].b.c`` (subscripts of the enclosing components must be constant; those of the last
        part index into the value)."""
        names = []
        for k, part in enumerate(parts):
            subs = part.get("subs") or []
            if subs and k < len(parts) - 1:
                picks = []
                for sub in subs:
                    val = self._subscript(sub, None, 0, env)
                    if not isinstance(val, int):
                        raise self.unsupported(f"assignment to an element of a component array with a "
                                               f"subscript that is not a constant ({part['ident']}[...])")
                    picks.append(str(val))
                names.append(f"{part['ident']}[{','.join(picks)}]")
            else:
                names.append(part["ident"])
        return ".".join(names)

    def _if_statement(self, body: Any, env: dict[str, Value], fname: str, conds: list[Value] | None = None) -> None:
        """An if-statement (or, given *conds*, the branches of a when-statement with their firings): in a
        function, one whose branches reach a while loop as a switch (:func:`.if_switch.switched_if`), else
        every branch run on a copy of *env* and the copies merged."""
        blocks = body.get("cond_blocks") or body.get("branches") or []
        else_block = body.get("else_block") or body.get("else_branch") or []
        chain: list[tuple[Any, list[Any]]] = []  # (condition, statements) that may be taken; None: the else
        for k, blk in enumerate(blocks):
            if isinstance(blk, dict):
                cond_node, stmts = blk.get("cond"), blk.get("stmts", blk.get("body", []))
            else:
                cond_node, stmts = blk
            cond = conds[k] if conds is not None else self.expr(cond_node, env)
            if is_number(cond):
                if bool(cond):
                    chain.append((None, stmts))
                    break
                continue
            chain.append((cond, stmts))
        else:
            chain.append((None, else_block or []))
        if conds is None and not _is_algorithm(fname) and switched_if(self, chain, env, fname):
            return
        conds_and_envs = []
        prior: list[Any] = []  # symbolic conditions of the branches before (for asserts in branches)
        for cond, stmts in chain:
            branch_env = dict(env)
            self._guarded(_branch_guard(cond, prior), stmts, branch_env, fname)
            if cond is not None:
                prior.append(cond)
            conds_and_envs.append((True if cond is None else cond, branch_env))
        # merge from the last branch backwards
        merged = conds_and_envs[-1][1]
        for cond, branch_env in reversed(conds_and_envs[:-1]):
            out = {}
            for key in set(branch_env) | set(merged):
                a = branch_env.get(key, env.get(key))
                b = merged.get(key, env.get(key))
                if a is None or b is None:
                    out[key] = a if b is None else b
                elif a is b:
                    out[key] = a
                else:
                    out[key] = arr.map2(lambda x, y, c=cond: ca.if_else(c, x, y), a, b, f"if-branches of {key!r}")
            merged = out
        env.clear()
        env.update(merged)

    def _guarded(self, guard: Any, stmts: list[Any], env: dict[str, Value], fname: str) -> None:
        if guard is not None:
            self._guards.append(guard)
        try:
            self._statements(stmts, env, fname)
        finally:
            if guard is not None:
                self._guards.pop()

    # ------------------------------------------------------------- asserts
    def add_assert(self, body: dict[str, Any], env: dict[str, Value] | None, origin: str) -> None:
        """Record ``assert(condition, message, level)``; *env* is a function's environment."""
        message = self._message_text(body.get("message"), env)
        saved, self._freeze = self._freeze, False  # an assert is checked as its condition stands (no events)
        try:
            cond = self.expr(body["condition"], env)
        finally:
            self._freeze = saved
        if isinstance(cond, np.ndarray):
            raise CompileError(f"the condition of assert({message!r}) in {origin} of {self.model} is an array")
        if is_number(cond) and not isinstance(cond, (bool, np.bool_)):
            raise CompileError(f"the condition of assert({message!r}) in {origin} of {self.model} is the "
                               f"number {cond!r}, not a Boolean")
        level = "error"
        if body.get("level") is not None:
            lv = self.expr(body["level"], env)  # AssertionLevel.warning = 1, error = 2
            if not is_number(lv):  # rumoca already refuses this (MLS 8.3.7); kept as a clear error
                raise CompileError(f"the level of assert({message!r}) in {origin} of {self.model} "
                                   "is not a constant")
            level = "warning" if int(lv) == 1 else "error"
        self._record_assert(cond, message, level, origin)

    def _record_assert(self, cond: Any, message: str, level: str, origin: str) -> None:
        for guard in self._guards:  # an assert in a function's if-branch only counts where it is taken
            cond = ca.logic_or(logical_not(guard), cond) if not is_number(cond) or not bool(cond) else cond
        if is_number(cond):
            cond = ca.MX(1.0 if bool(cond) else 0.0)
        elif not isinstance(cond, ca.MX):
            cond = ca.MX(cond)
        self.asserts.append(Assertion(condition=ca.if_else(cond, 1.0, 0.0), message=message,
                                      level=level, origin=origin))

    def _message_text(self, node: Any, env: dict[str, Value] | None) -> str:
        """The text of an assert message: literals and constant ``String(...)`` parts; others as ``<...>``."""
        kind, body = kind_of(node)
        if node is None:
            return "assertion failed"
        if kind == "Literal":
            val = body.get("value") or {}
            if isinstance(val, dict) and "String" in val:
                return str(val["String"])
            raise CompileError(f"the message of an assert in {self.model} is {literal_text(val)}, not a String")
        if kind == "Parenthesized":
            return self._message_text(body.get("expr", body.get("inner")), env)
        if kind == "Binary" and str(body.get("op")) in ("Add", "AddElem"):
            return self._message_text(body["lhs"], env) + self._message_text(body["rhs"], env)
        if kind == "VarRef":
            name = body["name"]["name"]
            sv = self.scalars.get(name)
            if sv is not None and sv.type == STRING:
                return str(sv.value)
        try:
            args = (body.get("args") or []) if isinstance(body, dict) else []
            fn = str(body.get("function") or (body.get("name") or {}).get("name", "")) if isinstance(body, dict) else ""
            if fn.lower() == "string" and args:
                val = self.expr(args[0], env)
                if is_number(val):
                    return f"{float(val):g}" if not isinstance(val, (bool, np.bool_)) else str(bool(val)).lower()
        except CompileError:
            pass
        return "<...>"

    def _for_statement(self, body: Any, env: dict[str, Value], fname: str) -> None:
        loop = marked_while(body)  # a while statement given to rumoca as a for loop (.while_source)
        if loop is not None:
            return while_statement(self, loop, env, fname)
        indices = body.get("indices") or []
        if len(indices) != 1:
            raise self.unsupported(f"for-loop with {len(indices)} indices {_in(fname)}")
        ident = indices[0].get("ident")
        name = ident.get("text") if isinstance(ident, dict) else ident
        rng = self.expr(indices[0]["range"], env)
        for value in rng:
            env[name] = value
            self._statements(body.get("equations") or body.get("stmts") or body.get("body") or [], env, fname)

    def algorithm_residuals(self, section: dict[str, Any], initial: bool) -> list[tuple[ca.MX, str]]:
        """An (initial) algorithm section as equations: ``v = value`` for each variable it assigns.

        The statements are executed symbolically, as a function body is inlined (assignments,
        if, for, assert): each assigned variable starts from its start value (MLS 11.1.2: a value
        read before the section assigns it) and ends as an expression in the other variables.
        A section is one vector equation whose unknowns are the variables it assigns: an initial
        algorithm determines them at initialisation (e.g. a ``fixed = false`` parameter), an
        algorithm for all time.
        """
        origin = section.get("origin")
        owner = str(origin).removeprefix("algorithm from ").strip() if isinstance(origin, str) else ""
        owner = owner if owner and owner != "(top level)" else self.model
        context = f"{'initial ' if initial else ''}algorithm of {owner}"
        env: dict[str, Value] = {}
        assigned: list[str] = []
        for out in section.get("outputs") or []:
            name = str(out.get("name") or "")
            base = name if name in self.vars else re.sub(r"\[[^\]]*\]$", "", name)
            if base not in self.vars:
                raise CompileError(f"the {context} in {self.model} assigns {name!r}, which is not a variable")
            if base in env:
                continue
            scalars = self.vars[base]
            if any(sv.sym is None for sv in scalars):
                raise CompileError(f"the {context} in {self.model} assigns {base!r}, which is a constant or "
                                   "a structural parameter")
            # a discrete variable starts from pre(v), any other from its start value (MLS 11.1.2)
            starts = [self.pre_sym(sv) if sv.kind == "discrete" else self._start_of(sv) for sv in scalars]
            env[base] = arr.from_list(starts).reshape(self.dims[base]) if self.dims[base] else starts[0]
            assigned.append(base)
        self._statements(section.get("statements") or [], env, context)
        out: list[tuple[ca.MX, str]] = []
        for base in assigned:
            value = env[base]
            for sv in self.vars[base]:
                v = value[tuple(i - 1 for i in sv.index)] if sv.index else value
                if arr.is_array(v):
                    raise CompileError(f"the {context} in {self.model} gives {sv.name} a value of size "
                                       f"{arr.size_text(arr.shape(v))}")
                if sv.kind == "discrete" and not initial:  # defined at events (a when-statement, pre(v))
                    self._discrete_defs.append((sv.sym - v, f"{context} ({sv.name})"))
                else:
                    out.append((sv.sym - v, f"{context} ({sv.name})"))
        return out
