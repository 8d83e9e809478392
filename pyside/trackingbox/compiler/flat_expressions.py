"""Expressions of the flat model as CasADi values (:class:`ExpressionTranslation`, a part of
:class:`.flatten.FlatTranslator`): literals, references, operators, if-expressions, arrays and
comprehensions, built-in and user function calls, the MSL's tables, ``der``; relations and
roundings held between events, ``pre``, when-conditions and when-equations (:mod:`.events`).
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ..errors import CompileError, UnsupportedConstructError
from . import arrays as arr
from . import records, tables
from .arrays import ArrayError
from .events import Condition, Sample, WhenCondition
from .source import Location, strip_comments
from .flat_model import ScalarVar, Value, kind_of
from .flat_builtins import (ARRAY_BUILTINS, BUILTIN_NAMES, EVENT_BUILTINS, UNSUPPORTED_BUILTINS, binary,
                            builtin_call, if_then, is_number, logical_and, logical_not, logical_or, plain_ge)
from .flat_text import expression_text, span_hint
from .records import Record

HYSTERESIS = 1e-10
"""Relative shift of event indicators past the switching point (see FlatTranslator.relation)."""


class ExpressionTranslation:
    """The expression part of :class:`.flatten.FlatTranslator` (its state is set up there)."""

    # ------------------------------------------------------------ expressions
    def expr(self, node: Any, env: dict[str, Value] | None = None) -> Value:
        kind, body = kind_of(node)
        if isinstance(body, dict) and isinstance(body.get("span"), dict):
            self._span = body["span"]
        method: Callable[[Any, dict[str, Value] | None], Value] | None = getattr(self, f"_x_{kind}", None)
        if method is None:
            raise self.unsupported(f"expression of kind {kind!r}")
        try:
            return method(body, env)
        except ArrayError as exc:
            # the innermost expression that failed names itself; outer ones pass the error on
            span = body.get("span") if isinstance(body, dict) else None
            hint = span_hint(body)
            locs = self.location(rf"\s*{re.escape(hint)}\b" if hint else None,
                                 span if isinstance(span, dict) else None)
            where = f" at {locs[0]}" if locs else ""
            raise CompileError(f"{exc} in `{expression_text(node)}` in {self.model}{where}") from None

    def _x_Literal(self, body: Any, env: Any) -> Value:
        kind, val = kind_of(body["value"])
        if kind in ("Real", "Integer"):
            return float(val) if kind == "Real" else int(val)
        if kind == "Boolean":
            return bool(val)
        if kind == "String":
            return str(val)
        raise self.unsupported(f"literal of kind {kind!r}")

    def _x_VarRef(self, body: Any, env: Any) -> Value:
        name = body["name"]["name"]
        return self.ref(name, body.get("subscripts") or [], env)

    def _x_Binary(self, body: Any, env: Any) -> Value:
        op = body["op"]
        if kind_of(body["lhs"])[0] == "Tuple":
            return self._tuple_equation(body, env)
        lhs = self.expr(body["lhs"], env)
        if str(op).lower() in ("and", "or") and is_number(lhs) and bool(lhs) == (str(op).lower() == "or"):
            return bool(lhs)  # false and ..., true or ...: the other operand is not evaluated
        rhs = self.expr(body["rhs"], env)
        if (isinstance(lhs, Record) or isinstance(rhs, Record)
                or records.is_record_array(lhs) or records.is_record_array(rhs)):
            if str(op) != "Sub":
                raise self.unsupported(f"operator {op!r} on a record")
            try:  # an equation between records: one per field (the only record operation in the model)
                return arr.from_list(records.difference(lhs, rhs, f"`{expression_text(body)}`"))
            except records.RecordError as exc:
                raise CompileError(f"{exc} in {self.model}") from None
        return binary(str(op), lhs, rhs, self)

    def _x_FieldAccess(self, body: Any, env: Any) -> Value:
        """``f(x).p``: a field of a record value (the front end passes a record argument so);
        ``mediums[1:n].state``: the field of each element of an array of components (.record_arrays)."""
        paths = self.component_paths({"FieldAccess": body}, env)
        if paths is not None:
            return self.path_value(paths)
        is_call = kind_of(body["base"])[0] == "FunctionCall"
        base = self.read_call(body["base"], env) if is_call else self.expr(body["base"], env)
        if records.is_record_array(base):  # the field of each element of an array of record values
            try:
                return records.field_of_each(base, str(body.get("field")), f"`{expression_text(body['base'])}`")
            except records.RecordError as exc:
                raise CompileError(f"{exc} in {self.model}") from None
        field = body.get("field")
        if not isinstance(base, Record):
            raise self.unsupported(f"field access `.{field}` on a value that is not a record")
        if field not in base:
            raise CompileError(f"record `{expression_text(body['base'])}` has no field {field!r} "
                               f"(fields: {', '.join(base)}) in {self.model}")
        return base[field]

    def _tuple_equation(self, body: Any, env: Any) -> Value:
        """``(a, , c) = f(x)``: one residual per output that is not omitted, flattened."""
        kind, call = kind_of(body["rhs"])
        if str(body["op"]).lower() != "sub" or kind != "FunctionCall":
            raise self.unsupported("tuple expression other than the left side of (a, b) = f(x)")
        fname = call["name"]["name"]
        fn = self.functions.get(fname)
        if fn is None:
            raise CompileError(f"call of unknown function {fname!r} in {self.model}")
        args = [self.expr(a, env) for a in (call.get("args") or [])]
        outs = self.inline(fname, fn, args)
        targets = body["lhs"]["Tuple"].get("elements") or []
        if len(targets) > len(outs):
            raise CompileError(f"{len(targets)} results taken from {fname!r}, which has {len(outs)} outputs, "
                               f"in {self.model}")
        residuals: list[Value] = []
        for target, out in zip(targets, outs):
            if kind_of(target)[0] == "Empty":
                continue
            residuals.extend(arr.elements([binary("Sub", self.expr(target, env), out, self)]))
        return arr.from_list(residuals)

    def _x_Index(self, body: Any, env: Any) -> Value:
        """A subscripted expression, e.g. ``f(x)[2]`` or an array input ``A[i]`` inside a function;
        ``statesFM[2:n+1]``, elements of an array of records or components (.record_arrays)."""
        paths = self.component_paths({"Index": body}, env)
        if paths is not None:
            return self.path_value(paths)
        base = self.expr(body["base"], env)
        subs = body.get("subscripts") or []
        return arr.subscript(base, [self._subscript(s, base, k, env, read=True) for k, s in enumerate(subs)],
                             f"`{expression_text(body['base'])}`")

    def _x_Unary(self, body: Any, env: Any) -> Value:
        op = body.get("op")
        arg = self.expr(body.get("rhs", body.get("arg", body.get("expr"))), env)
        opname = str(op).lower()
        if opname in ("minus", "neg", "sub", "dotminus", "elemminus", "negate", "subelem", "minuselem"):
            return arr.map1(lambda a: -a, arg)
        if opname in ("plus", "add", "dotplus", "addelem", "pluselem"):
            return arg
        if opname == "not":
            return arr.map1(logical_not, arg)
        raise self.unsupported(f"unary operator {op!r}")

    def _x_If(self, body: Any, env: Any) -> Value:
        branches = body["branches"]
        result = self.expr(body["else_branch"], env)
        for cond_node, val_node in reversed(branches):
            cond = self.expr(cond_node, env)
            if is_number(cond):
                if bool(cond):
                    result = self.expr(val_node, env)
                continue
            val = self.expr(val_node, env)
            if arr.is_array(cond):
                raise ArrayError("if-expression with an array condition")
            result = arr.map2(lambda a, b, c=cond: ca.if_else(c, a, b), val, result,
                              "if-expression branches", broadcast=False)
        return result

    def _x_Parenthesized(self, body: Any, env: Any) -> Value:
        return self.expr(body["inner"] if isinstance(body, dict) and "inner" in body else body, env)

    def _x_Array(self, body: Any, env: Any) -> Value:
        elements = body.get("elements", body) if isinstance(body, dict) else body
        kind = str(body.get("kind", "Array")) if isinstance(body, dict) else "Array"
        vals = [self.expr(e, env) for e in elements]
        if kind == "Horizontal":  # [a, b]: cat(2, promote(a, 2), promote(b, 2))
            return arr.cat(2, [arr.promote2(v) for v in vals], "matrix constructor [a, b]")
        if kind == "Vertical":  # [a; b]: cat(1, promote(a, 2), promote(b, 2))
            return arr.cat(1, [arr.promote2(v) for v in vals], "matrix constructor [a; b]")
        if kind != "Array":
            raise self.unsupported(f"array constructor of kind {kind!r}")
        if vals and not any(arr.is_array(v) for v in vals):
            where = self._multi_iterator_comprehension(body)
            if where is not None:
                raise UnsupportedConstructError(
                    f"unsupported Modelica construct in {self.model}: array comprehension with several "
                    f"iterators ({{e for i in u, j in v}}) at {where}: the front end flattens it into a vector, "
                    "losing its size; write nested comprehensions {{e for i in u} for j in v} instead"
                )
        return arr.stack(vals)

    _MULTI_ITERATOR = re.compile(r"\s*for\s+\w+\s+in\s+[^{};]*?,\s*\w+\s+in\b")

    def _multi_iterator_comprehension(self, body: Any) -> Location | None:
        """Where a vector came from ``{e for i in u, j in v}``, which rumoca flattens to one dimension.

        The flat vector carries the span of the element expression ``e``; the
        source text right after it shows the iterators.
        """
        span = body.get("span") if isinstance(body, dict) else None
        if not isinstance(span, dict) or not isinstance(span.get("end"), int):
            return None
        self.location()  # learns the model's files and the span source numbers
        known = (self._sources or {}).get(span.get("source"))
        files = (known,) if known is not None else (self._files or ())
        start, end = span.get("start", 0), span["end"]
        for file in files:
            text = self._code(file)
            if end > len(text) or text[start:end].lstrip().startswith(("{", "[")):
                continue
            if self._MULTI_ITERATOR.match(text, end):
                return Location(file, text.count("\n", 0, start) + 1)
        return None

    def _code(self, file: Path) -> str:
        """A file's text with comments and strings blanked (cached)."""
        if file not in self._text_cache:
            try:
                data = file.read_bytes()
            except OSError:
                data = b""
            if data.startswith(b"\xef\xbb\xbf"):
                data = data[3:]
            # spans are byte offsets: keep one character per byte
            self._text_cache[file] = strip_comments(data.decode("latin-1"))
        return self._text_cache[file]

    def _x_ArrayComprehension(self, body: Any, env: Any) -> Value:
        """``{e for i in u, j in v}`` = ``{{e for i in u} for j in v}`` (MLS 10.4.2)."""
        if body.get("filter") is not None:
            raise self.unsupported("array comprehension with an if-filter", r"\bfor\b[^;]*\bif\b")
        indices = body.get("indices") or []
        if not indices:
            raise self.unsupported("array comprehension without an iterator")
        ranges = []
        for ix in indices:
            if ix.get("range") is None:
                raise self.unsupported("array comprehension with an implicit range", r"\bfor\s+\w+\s*[},]")
            rng = self.expr(ix["range"], env)
            if not arr.is_array(rng) or len(rng.shape) != 1:
                raise ArrayError(f"iterator {ix['name']!r} ranges over a value of size {arr.size_text(arr.shape(rng))}")
            ranges.append((ix["name"], list(rng)))

        def build(level: int, scope: dict[str, Value]) -> Value:
            # the last iterator is the outermost dimension
            if level < 0:
                return self.expr(body["expr"], scope)
            name, values = ranges[level]
            return arr.stack([build(level - 1, {**scope, name: v}) for v in values], "array comprehension")

        return build(len(ranges) - 1, dict(env or {}))

    def _x_Range(self, body: Any, env: Any) -> Value:
        start = self.expr(body["start"], env)
        step = self.expr(body["step"], env) if body.get("step") is not None else 1
        end = self.expr(body["end"], env)
        if not all(is_number(v) for v in (start, step, end)):
            raise self.unsupported("range with non-constant bounds")
        if float(step) == 0.0:
            raise ArrayError("range with step 0")
        count = max(0, math.floor((float(end) - float(start)) / float(step) + 1e-10) + 1)
        integer = all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (start, step, end))
        return arr.from_list([start + k * step if integer else float(start) + k * float(step) for k in range(count)])

    def _x_BuiltinCall(self, body: Any, env: Any) -> Value:
        fn = str(body["function"])
        args_nodes = body.get("args") or []
        lname = fn.lower()
        if lname == "der":
            return self._der(args_nodes[0], env)
        if lname in UNSUPPORTED_BUILTINS:
            raise self.unsupported(f"built-in {lname}()", UNSUPPORTED_BUILTINS[lname])
        if lname in EVENT_BUILTINS:
            return self._event_builtin(lname, args_nodes, env)
        if lname in ("noevent", "smooth"):  # relations inside generate no events
            saved, self._freeze = self._freeze, False
            try:
                args = [self.expr(a, env) for a in args_nodes]
            finally:
                self._freeze = saved
            return builtin_call(lname, args, self)
        args = [self.expr(a, env) for a in args_nodes]
        return builtin_call(lname, args, self)

    # --------------------------------------------------------------- events
    def _is_continuous(self, value: Value) -> bool:
        """Whether *value* depends on a continuous-time variable (or time): a relation on it switches
        between events and must be frozen (.events)."""
        if is_number(value) or not isinstance(value, ca.MX):
            return False
        for s in ca.symvar(value):
            name = s.name()
            if name == "time" or name.startswith("der("):
                return True
            sv = self.scalars.get(name)
            if sv is not None and sv.kind in ("continuous", "input"):
                return True
        return False

    def relation(self, op: str, a: Value, b: Value) -> Value:
        """``a op b`` with its Modelica meaning: a relation on continuous-time values outside
        ``noEvent`` is frozen between events, with the event indicator ``a - b``."""
        if (is_number(a) and is_number(b)) or (isinstance(a, str) and isinstance(b, str)):
            return {"<": a < b, "<=": a <= b, ">": a > b, ">=": a >= b, "==": a == b, "!=": a != b}[op]
        x, y = (ca.MX(a) if is_number(a) else a), (ca.MX(b) if is_number(b) else b)
        value = {"<": x < y, "<=": x <= y, ">": x > y, ">=": x >= y, "==": x == y, "!=": x != y}[op]
        if op in ("==", "!=") or not self._freeze or not self._is_continuous(x - y):
            return value
        key = f"rel|{value}"  # the same relation in several equations is one condition
        if key in self._frozen:
            return self._frozen[key]
        sym = ca.MX.sym(f"_tbx_c{len(self.events.conditions) + 1}")
        # indicator: positive where the relation holds, shifted by a hysteresis so that at the located
        # crossing the relation has clearly changed (else an event found a hair early changes nothing
        # and the crossing is never seen again)
        towards = x - y if op in (">", ">=") else y - x
        eps = HYSTERESIS * (1 + ca.fabs(x) + ca.fabs(y))
        indicator = towards + ca.if_else(sym, eps, -eps)
        self.events.conditions.append(Condition(sym, "rel", value, [indicator], f"{x} {op} {y}"[:200]))
        self._frozen[key] = sym
        return sym

    def rounding(self, kind: str, a: Value) -> Value:
        """``floor``/``integer``/``ceil`` of a continuous-time value: held between events, with event
        indicators at the next integers either side (MLS 3.7.2: these functions generate events)."""
        value = ca.ceil(a) if kind == "ceil" else ca.floor(a)
        if not self._freeze or not self._is_continuous(a):
            return value
        sym = ca.MX.sym(f"_tbx_c{len(self.events.conditions) + 1}")
        lower, upper = (sym - 1, sym) if kind == "ceil" else (sym, sym + 1)
        eps = HYSTERESIS * (1 + ca.fabs(a))  # crossings are located just past the next integer (see relation)
        self.events.conditions.append(Condition(sym, kind, value, [a - lower + eps, upper + eps - a],
                                                f"{kind}({a})"[:200]))
        return sym

    def pre_sym(self, sv: ScalarVar) -> ca.MX:
        """The symbol of ``pre(v)`` for a discrete variable."""
        if sv.name not in self._pre:
            self._pre[sv.name] = ca.MX.sym(f"pre({sv.name})")
        return self._pre[sv.name]

    def pre_continuous_sym(self, sv: ScalarVar) -> ca.MX:
        """The symbol of ``pre(y)`` for a continuous-time *y* (in a when-clause: MLS 3.7.5): its left
        limit, held by the FMU (.events: set to y at each step of the event iteration)."""
        if sv.name not in self._pre_continuous:
            self._pre_continuous[sv.name] = ca.MX.sym(f"pre({sv.name})")
        return self._pre_continuous[sv.name]

    def _pre_value(self, node: Any) -> Value:
        """``pre(v)``: the value of *v* before the current event-iteration step; for a continuous-time
        variable its value before the event (its left limit), then before each step."""
        value = self.expr(node, None)

        def one(x: Value) -> Value:
            if is_number(x) or not isinstance(x, ca.MX):
                return x
            olds, news = [], []
            for s in ca.symvar(x):
                sv = self.scalars.get(s.name())
                if sv is not None and sv.kind == "discrete":
                    olds.append(s)
                    news.append(self.pre_sym(sv))
                elif sv is not None and sv.kind == "continuous":
                    olds.append(s)
                    news.append(self.pre_continuous_sym(sv))
            return ca.substitute([x], olds, news)[0] if olds else x

        return arr.map1(one, value)

    def _event_builtin(self, name: str, nodes: list[Any], env: Any) -> Value:
        if name == "pre":
            return self._pre_value(nodes[0])
        if name == "edge":
            b, p = self.expr(nodes[0], env), self._pre_value(nodes[0])
            return arr.map2(lambda x, y: logical_and(x, logical_not(y)), b, p, "edge()", broadcast=False)
        if name == "change":
            v, p = self.expr(nodes[0], env), self._pre_value(nodes[0])
            return arr.map2(lambda x, y: x != y, v, p, "change()", broadcast=False)
        if name == "initial":
            self._uses_initial = True
            return self.events.initial
        if name == "terminal":
            return False
        if name == "sample":  # true at its instants only (the FMU's event iteration, .events)
            start, interval = (self.expr(n, env) for n in nodes[:2])
            if arr.is_array(start) or arr.is_array(interval):
                raise CompileError(f"sample() with an array argument in {self.model}")
            sym = ca.MX.sym(f"_tbx_s{len(self.events.samples) + 1}")
            self.events.samples.append(Sample(sym, ca.MX(start) if is_number(start) else start,
                                              ca.MX(interval) if is_number(interval) else interval))
            return sym
        raise self.unsupported(f"built-in {name}()")  # pragma: no cover - EVENT_BUILTINS lists the above

    def when_fire(self, node: Any, env: Any) -> Value:
        """The firing of a when condition (``c and not pre(c)`` for each element of it); each element
        becomes a held when condition of the event iteration."""
        cond = self.expr(node, env)
        fire: Value = False
        for el in (list(cond.ravel()) if arr.is_array(cond) else [cond]):
            if is_number(el):
                continue  # a constant condition never becomes true
            k = len(self.events.whens) + 1
            sym, pre = ca.MX.sym(f"_tbx_w{k}"), ca.MX.sym(f"pre(_tbx_w{k})")
            initial = bool(ca.depends_on(el, self.events.initial))
            self.events.whens.append(WhenCondition(sym, pre, el, initial))
            edge = ca.logic_and(sym, ca.logic_not(pre))
            if not initial:  # a when-clause fires at initialisation only by initial()
                edge = ca.logic_and(edge, ca.logic_not(self.events.initial))
            fire = logical_or(fire, edge)
        return fire

    def when_chain(self, chain: dict[str, Any]) -> list[tuple[ca.MX, str]]:
        """A when-equation with its elsewhen branches: ``v = (if fire1 then e1 elseif ... else pre(v))``
        for each variable assigned, and the re-initialisations of states."""
        branches = [chain.get("first") or {}, *(chain.get("else_when") or [])]
        fires = [self.when_fire(br.get("condition"), None) for br in branches]
        assigns: dict[str, dict[int, Value]] = {}
        reinits: dict[str, dict[int, Value]] = {}
        for bi, br in enumerate(branches):
            for eq in br.get("equations") or []:
                kind, body = kind_of(eq)
                if kind in ("Assign", "Reinit"):
                    target = str(body.get("target") if kind == "Assign" else body.get("state"))
                    value = self.expr(body.get("value"))
                    for sv, v in self._scalar_targets(target, value, "when-clause"):
                        (assigns if kind == "Assign" else reinits).setdefault(sv.name, {})[bi] = v
                elif kind == "Assert":
                    self._guards.append(fires[bi])
                    try:
                        self.add_assert(body, None, f"when-clause of {self.model}")
                    finally:
                        self._guards.pop()
                else:
                    word = kind[:1].lower() + kind[1:]
                    raise self.unsupported(f"{word}() in a when-clause", rf"\b{word}\s*\(")
        out: list[tuple[ca.MX, str]] = []
        for name, by_branch in assigns.items():
            sv = self.scalars[name]
            if sv.kind != "discrete":  # pragma: no cover - targets of when-clauses are made discrete
                raise CompileError(f"when-clause assigns {name!r}, which is not a discrete variable")
            expr: Value = self.pre_sym(sv)
            for bi in reversed(range(len(branches))):
                expr = if_then(fires[bi], by_branch.get(bi, self.pre_sym(sv)), expr)
            self._discrete_defs.append((sv.sym - expr, f"when-clause assignment to {name}"))
        for name, by_branch in reinits.items():
            sv = self.scalars[name]
            if sv.kind != "continuous":
                raise self.unsupported(f"reinit({name}) of a variable that is not a state", r"\breinit\s*\(")
            expr = sv.sym
            for bi in reversed(range(len(branches))):
                expr = if_then(fires[bi], by_branch.get(bi, sv.sym), expr)
            self.events.reinits.append((sv.sym, expr))
        return out

    def _scalar_targets(self, target: str, value: Value, what: str) -> list[tuple[ScalarVar, Value]]:
        """The scalars of an assignment's target (a variable, an array, or one element) with their values."""
        if target in self.scalars:
            if arr.is_array(value):
                raise CompileError(f"{what} in {self.model} gives {target} a value of size "
                                   f"{arr.size_text(arr.shape(value))}")
            return [(self.scalars[target], value)]
        if target in self.vars:
            scalars = self.vars[target]
            dims = self.dims[target]
            if not dims:
                return [(scalars[0], value)]
            if not arr.is_array(value) or arr.shape(value) != dims:
                raise CompileError(f"{what} in {self.model} gives {target} of size {arr.size_text(dims)} a value "
                                   f"of size {arr.size_text(arr.shape(value))}")
            return [(sv, value[tuple(i - 1 for i in sv.index)]) for sv in scalars]
        raise CompileError(f"{what} in {self.model} assigns {target!r}, which is not a variable of the model")

    def _x_FunctionCall(self, body: Any, env: Any) -> Value:
        fname = body["name"]["name"]
        if fname in tables.FUNCTIONS:
            return self._table_call(fname, body.get("args") or [], env)
        args = [self.expr(a, env) for a in (body.get("args") or [])]
        if fname in BUILTIN_NAMES or (fname.lower() in ARRAY_BUILTINS and fname not in self.functions):
            return builtin_call(fname.lower(), args, self)
        fn = self.functions.get(fname)
        if fn is None:
            raise CompileError(f"call of unknown function {fname!r} in {self.model}")
        if fn.get("is_constructor"):
            return self.record_constructor(fname, fn, args)
        outs = self.inline(fname, fn, args)
        if not outs:
            raise CompileError(f"function {fname!r}, which has no output, called in an expression in {self.model}")
        return outs[0]

    # --------------------------------------------------------------- tables
    def _table_call(self, fname: str, nodes: list[Any], env: Any) -> Value:
        """A call of the MSL's table functions on a table object (.tables)."""
        kind, ref = kind_of(nodes[0]) if nodes else ("", None)
        if kind != "VarRef":
            raise self.unsupported(f"call of {fname} on a table object that is not a parameter")
        tab = self._table(ref["name"]["name"])
        args = [self.expr(a, env) for a in nodes[1:]]
        try:
            if fname in tables.TIME_VALUE | tables.ONE_D_VALUE:
                icol = int(self.numeric(args[0], f"column of table {tab.name}"))
                if tab.kind == "time":
                    def ge(a: Value, b: Value) -> Value:
                        # table points are time events (MSL timeEvents); otherwise plain comparisons
                        events = tab.smoothness == tables.CONSTANT or tab.time_events != tables.NO_TIME_EVENTS
                        return self.relation(">=", a, b) if events else plain_ge(a, b)
                else:
                    ge = plain_ge
                return tables.value(tab, icol, args[1], ge, self._table_range_assert(tab),
                                    floor=lambda e: self.rounding("floor", e) if self._freeze else ca.floor(e))
            if fname == tables.TIME_NEXT:
                return tables.next_event(tab, args[0])
            if fname in (tables.TIME_MIN, tables.ONE_D_MIN):
                return tab.grid[0]
            if fname in (tables.TIME_MAX, tables.ONE_D_MAX):
                return tab.grid[-1]
        except tables.TableError as exc:
            raise self.unsupported(str(exc), r"\bCombi(?:Time)?Table") from None
        raise self.unsupported(f"table function {fname}")  # pragma: no cover - FUNCTIONS lists the above

    def _table_range_assert(self, tab: tables.Table) -> Callable[[Value, Value], None]:
        def check(lo: Value, hi: Value) -> None:
            self._record_assert(logical_and(lo, hi), f"extrapolation error: the abscissa is outside the table {tab.name} "
                                f"[{tab.grid[0]:g}, {tab.grid[-1]:g}] (NoExtrapolation)", "error", tab.name)
        return check

    def _table(self, name: str) -> tables.Table:
        """The table object bound to the parameter *name* (its constructor call's arguments evaluated)."""
        cache = self.__dict__.setdefault("_tables", {})
        if name in cache:
            return cache[name]
        var = (self.flat.get("variables") or {}).get(name) or {}
        kind, call = kind_of(var.get("binding"))
        cname = (call.get("name") or {}).get("name") if kind == "FunctionCall" and isinstance(call, dict) else None
        if cname not in (tables.TIME_CONSTRUCTOR, tables.ONE_D_CONSTRUCTOR,
                         tables.TIME_CONSTRUCTOR + ".constructor", tables.ONE_D_CONSTRUCTOR + ".constructor"):
            raise self.unsupported(f"table object {name} not built by the MSL's table constructor")
        saved, self._freeze = self._freeze, False
        try:
            args = [self.expr(a) for a in call.get("args") or []]
        finally:
            self._freeze = saved
        owner = name.rsplit(".", 1)[0] if "." in name else name
        try:
            tab = tables.from_constructor("time" if cname.startswith(tables.TIME_CONSTRUCTOR) else "1d", owner, args,
                                          lambda v, what: self.numeric(v, what))
        except tables.TableError as exc:
            raise self.unsupported(str(exc), r"\bCombi(?:Time)?Table") from None
        cache[name] = tab
        return tab

    def _der(self, node: Any, env: Any) -> Value:
        kind, body = kind_of(node)
        if kind != "VarRef":
            raise self.unsupported("der() of an expression", r"\bder\s*\(", "write der(x) of a variable")
        val = self._x_VarRef(body, env)
        return arr.map1(self._der_scalar, val)

    def _der_scalar(self, sym: Value) -> ca.MX:
        if not isinstance(sym, ca.MX) or not sym.is_symbolic():
            raise self.unsupported("der() of a parameter or constant")
        name = sym.name()
        sv = self.scalars.get(name)
        if sv is None or sv.kind != "continuous":
            raise self.unsupported(f"der() of {name!r}, which is not a continuous variable")
        if name not in self.der_placeholders:
            self.der_placeholders[name] = ca.MX.sym(f"der({name})")
        return self.der_placeholders[name]
