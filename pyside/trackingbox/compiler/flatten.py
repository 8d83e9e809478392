"""From rumoca's flattened model to an explicit, causalised CasADi model.

rumoca (pinned; its JSON schema is internal) parses, resolves and flattens the
Modelica source. This module reads the flat model (``Model.to_dict("flat")``):

* array variables are scalarised (``Th[3]``), structural parameters (Integer,
  Boolean) and constants are evaluated, every Real parameter becomes a symbol;
* expressions become CasADi ``MX`` expressions; Modelica functions are inlined
  symbolically (assignments, if-statements, for-loops over constant ranges);
* the equations are matched to their unknowns and sorted into blocks
  (:mod:`.causalize`): a scalar block linear in its unknown is solved
  symbolically, anything else goes to a Newton rootfinder.

Conditions (``if`` expressions, ``min``/``max``/``abs``) are evaluated as they
stand at each right-hand-side call: there is no event detection, so the
integrator crosses a switch like any other steep change. ``noEvent`` and
``smooth`` are therefore accepted and change nothing.

Anything else (when-clauses, algorithm sections in models, discrete variables,
``pre``/``edge``/``sample``/``reinit``, external functions, initial equations
other than start values) raises :class:`UnsupportedConstructError` naming the
construct and where it stands.
"""
from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ..errors import CompileError, UnsupportedConstructError
from .causalize import StructuralError, blt
from .source import Location, ModelicaSource, locate, model_files, span_location, span_sources

log = logging.getLogger(__name__)

REAL, INTEGER, BOOLEAN, STRING = 0, 1, 2, 3

Value = Any  # float | bool | ca.MX | np.ndarray (object array of the former)


@dataclass
class ScalarVar:
    """One scalar of a flattened variable."""

    name: str
    kind: str  # "parameter" | "structural" | "constant" | "input" | "continuous"
    type: int
    top_level: bool
    output: bool
    start_node: Any
    binding_node: Any
    index: tuple[int, ...]
    attrs: dict[str, Any]
    description: str | None
    fixed: bool | None = None
    sym: ca.MX | None = None
    value: Any = None  # evaluated value for structural/constant


@dataclass
class ExplicitModel:
    """The causalised model, ready for FMU export.

    ``assignments`` are in evaluation order; each assigns an unknown symbol (an
    algebraic variable, a calculated parameter, or a state derivative
    placeholder) an expression in states, inputs, parameters, time and earlier
    unknowns.
    """

    name: str
    time: ca.MX
    parameters: list[ScalarVar]
    calculated: list[ScalarVar]
    inputs: list[ScalarVar]
    states: list[ScalarVar]
    algebraics: list[ScalarVar]
    derivative: dict[str, ca.MX]  # state name -> placeholder symbol of der(state)
    assignments: list[tuple[ca.MX, ca.MX]]
    n_loops: int = 0
    loop_sizes: list[int] = field(default_factory=list)
    unused_parameters: list[str] = field(default_factory=list)
    torn_sizes: list[tuple[int, int]] = field(default_factory=list)


def _kind_of(node: Any) -> tuple[str, Any]:
    if isinstance(node, dict) and len(node) == 1:
        key = next(iter(node))
        return key, node[key]
    return type(node).__name__, node


_UNSUPPORTED_BUILTINS = {
    "pre": r"\bpre\s*\(",
    "edge": r"\bedge\s*\(",
    "change": r"\bchange\s*\(",
    "sample": r"\bsample\s*\(",
    "reinit": r"\breinit\s*\(",
    "delay": r"\bdelay\s*\(",
    "initial": r"\binitial\s*\(\s*\)",
    "terminal": r"\bterminal\s*\(\s*\)",
    "spatialdistribution": r"\bspatialDistribution\s*\(",
    "cardinality": r"\bcardinality\s*\(",
    "assert": r"\bassert\s*\(",
    "terminate": r"\bterminate\s*\(",
    "hold": r"\bhold\s*\(",
    "previous": r"\bprevious\s*\(",
    "subsample": r"\bsubSample\s*\(",
    "supersample": r"\bsuperSample\s*\(",
    "shiftsample": r"\bshiftSample\s*\(",
    "backsample": r"\bbackSample\s*\(",
    "noclock": r"\bnoClock\s*\(",
    "interval": r"\binterval\s*\(",
    "clock": r"\bClock\s*\(",
}


def _num(x: Value) -> bool:
    return isinstance(x, (int, float, bool, np.integer, np.floating, np.bool_))


class FlatTranslator:
    """Translate one rumoca flat model into an :class:`ExplicitModel`."""

    def __init__(self, flat: dict[str, Any], source: ModelicaSource, model: str):
        self.flat = flat
        self.source = source
        self.model = model
        self.types = flat.get("effective_types", {})
        self.functions = flat.get("functions", {}) or {}
        self.vars: dict[str, list[ScalarVar]] = {}
        self.scalars: dict[str, ScalarVar] = {}
        self.dims: dict[str, tuple[int, ...]] = {}
        self.time = ca.MX.sym("time")
        self.der_placeholders: dict[str, ca.MX] = {}
        self._evaluating: set[str] = set()
        self._inline_depth = 0
        self._span: dict[str, Any] | None = None  # span of the expression being translated (for errors)
        self._files: tuple[Path, ...] | None = None
        self._sources: dict[int, Path] | None = None

    # ------------------------------------------------------------------ errors
    def location(self, pattern: str | None = None, span: dict[str, Any] | None = None) -> list[Location]:
        """Where a construct stands: the model's own file (or a class it uses) and the line.

        From the front end's *span* (default: the expression being translated) when it
        matches *pattern*; else from a search for *pattern* restricted to the files of
        the classes the model uses (:func:`.source.locate`), never other files of the package.
        """
        if self._files is None:
            self._files = model_files(self.source, self.model)
            self._sources = span_sources(self.flat, self._files)
        span = span if span is not None else self._span
        if span is not None:
            known = self._sources.get(span.get("source")) if self._sources else None
            files = (known,) if known is not None else self._files
            loc = span_location(span, files, pattern)
            if loc is not None:
                return [loc]
        if pattern:
            locs = locate(self.source, self.model, pattern)
            if locs:
                return locs
        if span is not None and pattern:
            loc = span_location(span, files, None)
            if loc is not None:
                return [loc]
        return []

    def unsupported(self, construct: str, pattern: str | None = None, detail: str = "", *,
                    span: dict[str, Any] | None = None) -> UnsupportedConstructError:
        locs = self.location(pattern, span)
        where = (" at " + ", ".join(str(loc) for loc in locs)) if locs else ""
        msg = (
            f"unsupported Modelica construct in {self.model}: {construct}{where}"
            f"{': ' + detail if detail else ''}. The embedded backend cannot compile it; "
            "use --backend openmodelica where omc is installed, or rewrite the model"
        )
        return UnsupportedConstructError(msg)

    # --------------------------------------------------------------- checks
    def check_constructs(self) -> None:
        flat = self.flat
        if flat.get("when_chains"):
            raise self.unsupported("when-clause", r"\bwhen\b")
        if flat.get("algorithms"):
            raise self.unsupported("algorithm section in a model", r"\balgorithm\b")
        if flat.get("initial_algorithms"):
            raise self.unsupported("initial algorithm section", r"\binitial\s+algorithm\b")
        if flat.get("initial_equations"):
            raise self.unsupported(
                "initial equation section", r"\binitial\s+equation\b",
                "set start values with fixed = true instead",
            )
        for fname, fn in self.functions.items():
            if fn.get("external"):
                raise self.unsupported(f"external function {fname!r}", r"\bexternal\b")

    # ------------------------------------------------------------ variables
    def _type_of(self, v: dict[str, Any]) -> int:
        t = self.types.get(str(v.get("type_id")))
        if t is None:
            return REAL
        return int(t.get("canonical_type", REAL))

    def collect_variables(self) -> None:
        top_inputs = set(self.flat.get("top_level_input_components") or [])
        for name, v in self.flat["variables"].items():
            vtype = self._type_of(v)
            var_kind, _ = _kind_of(v.get("variability"))
            caus_kind, _ = _kind_of(v.get("causality"))
            ref = v.get("component_ref") or {}
            parts = ref.get("parts") or []
            top = len(parts) <= 1 and "." not in name
            if vtype not in (REAL, INTEGER, BOOLEAN):
                if var_kind in ("Parameter", "Constant"):
                    continue  # String parameters and the like: not part of the numeric model
                raise self.unsupported(
                    f"variable {name!r} of a non-numeric type",
                    rf"\b{name.rsplit('.', 1)[-1]}\b",
                )
            if var_kind == "Constant":
                kind = "constant"
            elif var_kind == "Parameter":
                kind = "parameter" if vtype == REAL else "structural"
            elif var_kind == "Discrete" or vtype != REAL:
                short = name.rsplit(".", 1)[-1]
                raise self.unsupported(
                    f"discrete variable {name!r}", rf"\b(?:discrete|Integer|Boolean)\b[^;]*\b{short}\b",
                    "only Real variables are supported; make it a parameter or a Real",
                )
            elif caus_kind == "Input" and (name in top_inputs or top):
                kind = "input"
            else:
                kind = "continuous"
            dims = self._dims(v.get("dims") or [], name)
            self.dims[name] = dims
            attrs = {k: v.get(k) for k in ("min", "max", "nominal", "unit", "display_unit")}
            desc = v.get("description")
            fixed_raw = v.get("fixed")
            scalars = []
            for idx in itertools.product(*[range(1, d + 1) for d in dims]) if dims else [()]:
                sname = name + ("[" + ",".join(str(i) for i in idx) + "]" if idx else "")
                sv = ScalarVar(
                    name=sname, kind=kind, type=vtype, top_level=top,
                    output=(caus_kind == "Output" and top), start_node=v.get("start"),
                    binding_node=v.get("binding"), index=idx, attrs=attrs, description=desc,
                    fixed=self._fixed(fixed_raw),
                )
                if kind in ("parameter", "input", "continuous"):
                    sv.sym = ca.MX.sym(sname)
                scalars.append(sv)
                self.scalars[sname] = sv
            self.vars[name] = scalars

    @staticmethod
    def _fixed(raw: Any) -> bool | None:
        if isinstance(raw, list) and raw:
            raw = raw[0]
        if isinstance(raw, bool):
            return raw
        return None

    def _dims(self, dims: list[Any], name: str) -> tuple[int, ...]:
        out = []
        for d in dims:
            if isinstance(d, int):
                out.append(d)
            else:
                val = self.expr(d)
                if not _num(val):
                    raise CompileError(f"array size of {name!r} in {self.model} is not a constant")
                out.append(int(val))
        return tuple(out)

    # -------------------------------------------------------- value lookup
    def _element(self, sv: ScalarVar, node: Any) -> Value:
        """Evaluate an attribute node (start/binding) for one scalar of an array."""
        val = self.expr(node)
        if isinstance(val, np.ndarray):
            if not sv.index:
                raise CompileError(f"array value for scalar {sv.name!r} in {self.model}")
            return val[tuple(i - 1 for i in sv.index)]
        return val

    def structural_value(self, sv: ScalarVar) -> Any:
        if sv.value is not None:
            return sv.value
        if sv.name in self._evaluating:
            raise CompileError(f"parameter {sv.name!r} in {self.model} depends on itself")
        self._evaluating.add(sv.name)
        try:
            node = sv.binding_node if sv.binding_node is not None else sv.start_node
            if node is None:
                val: Any = False if sv.type == BOOLEAN else 0
            else:
                val = self._element(sv, node)
            if not _num(val):
                raise CompileError(
                    f"{'constant' if sv.kind == 'constant' else 'structural parameter'} {sv.name!r} "
                    f"in {self.model} does not evaluate to a number"
                )
            if sv.type == BOOLEAN:
                val = bool(val)
            elif sv.type == INTEGER:
                val = int(round(float(val)))
            else:
                val = float(val)
            sv.value = val
            return val
        finally:
            self._evaluating.discard(sv.name)

    def numeric(self, value: Value, what: str) -> float:
        """Evaluate *value* with every parameter at its start value."""
        if _num(value):
            return float(value)
        if isinstance(value, ca.MX):
            syms = ca.symvar(value)
            if not syms:
                return float(ca.evalf(value))
            vals = []
            for s in syms:
                sv = self.scalars.get(s.name())
                if sv is None or sv.kind != "parameter":
                    raise CompileError(f"{what} in {self.model} depends on the variable {s.name()!r}")
                vals.append(self.parameter_start(sv))
            return float(ca.evalf(ca.substitute(value, ca.vertcat(*syms), ca.DM(vals))))
        raise CompileError(f"{what} in {self.model} is not a number")

    def parameter_start(self, sv: ScalarVar) -> float:
        if sv.value is not None:
            return float(sv.value)
        if sv.name in self._evaluating:
            raise CompileError(f"parameter {sv.name!r} in {self.model} depends on itself")
        self._evaluating.add(sv.name)
        try:
            node = sv.binding_node if sv.binding_node is not None else sv.start_node
            val = 0.0 if node is None else self.numeric(self._element(sv, node), f"value of {sv.name!r}")
        finally:
            self._evaluating.discard(sv.name)
        sv.value = val
        return val

    def ref(self, name: str, subs: list[Any], env: dict[str, Value] | None) -> Value:
        if env is not None and name in env:
            val = env[name]
            if subs:
                idx = tuple(self._index(s) - 1 for s in subs)
                return val[idx] if isinstance(val, np.ndarray) else val
            return val
        if name == "time":
            return self.time
        if name not in self.vars:
            # component_ref names of array elements of components come as "a[2].b"
            raise CompileError(f"unknown variable {name!r} referenced in {self.model}")
        scalars = self.vars[name]
        dims = self.dims[name]
        if subs:
            idx = tuple(self._index(s) for s in subs)
            if len(idx) != len(dims):
                return self._slice(name, dims, idx)
            sname = name + "[" + ",".join(str(i) for i in idx) + "]"
            if sname not in self.scalars:
                raise CompileError(f"index {list(idx)} out of range for {name!r} in {self.model}")
            return self._scalar_value(self.scalars[sname])
        if dims:
            arr = np.empty(dims, dtype=object)
            for sv in scalars:
                arr[tuple(i - 1 for i in sv.index)] = self._scalar_value(sv)
            return arr
        return self._scalar_value(scalars[0])

    def _slice(self, name: str, dims: tuple[int, ...], idx: tuple[int, ...]) -> Value:
        full = self.ref(name, [], None)
        return full[tuple(i - 1 for i in idx)]

    def _scalar_value(self, sv: ScalarVar) -> Value:
        if sv.kind in ("structural", "constant"):
            return self.structural_value(sv)
        return sv.sym

    def _index(self, sub: Any) -> int:
        kind, body = _kind_of(sub)
        if kind == "Index":
            return int(body["value"])
        if kind == "Expr":
            val = self.expr(body["expr"])
            if not _num(val):
                raise CompileError(f"non-constant array index in {self.model}")
            return int(round(float(val)))
        raise self.unsupported(f"array subscript {kind!r} (slices)")

    # ------------------------------------------------------------ expressions
    def expr(self, node: Any, env: dict[str, Value] | None = None) -> Value:
        kind, body = _kind_of(node)
        if isinstance(body, dict) and isinstance(body.get("span"), dict):
            self._span = body["span"]
        method: Callable[[Any, dict[str, Value] | None], Value] | None = getattr(self, f"_x_{kind}", None)
        if method is None:
            raise self.unsupported(f"expression of kind {kind!r}")
        return method(body, env)

    def _x_Literal(self, body: Any, env: Any) -> Value:
        kind, val = _kind_of(body["value"])
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
        lhs = self.expr(body["lhs"], env)
        rhs = self.expr(body["rhs"], env)
        return _binary(op, lhs, rhs, self)

    def _x_Unary(self, body: Any, env: Any) -> Value:
        op = body.get("op")
        arg = self.expr(body.get("rhs", body.get("arg", body.get("expr"))), env)
        opname = str(op).lower()
        if opname in ("minus", "neg", "sub", "dotminus", "elemminus", "negate"):
            return _elementwise(lambda a: -a, arg)
        if opname in ("plus", "add", "dotplus"):
            return arg
        if opname == "not":
            return _elementwise(_not, arg)
        raise self.unsupported(f"unary operator {op!r}")

    def _x_If(self, body: Any, env: Any) -> Value:
        branches = body["branches"]
        result = self.expr(body["else_branch"], env)
        for cond_node, val_node in reversed(branches):
            cond = self.expr(cond_node, env)
            if _num(cond):
                if bool(cond):
                    result = self.expr(val_node, env)
                continue
            val = self.expr(val_node, env)
            result = _elementwise2(lambda a, b: ca.if_else(cond, a, b), val, result)
        return result

    def _x_Parenthesized(self, body: Any, env: Any) -> Value:
        return self.expr(body["inner"] if isinstance(body, dict) and "inner" in body else body, env)

    def _x_Array(self, body: Any, env: Any) -> Value:
        elements = body.get("elements", body) if isinstance(body, dict) else body
        vals = [self.expr(e, env) for e in elements]
        arr = np.empty(len(vals), dtype=object)
        for i, v in enumerate(vals):
            arr[i] = v
        if vals and isinstance(vals[0], np.ndarray):
            return np.array([list(v) for v in vals], dtype=object)
        return arr

    def _x_Range(self, body: Any, env: Any) -> Value:
        start = self.expr(body["start"], env)
        step = self.expr(body["step"], env) if body.get("step") is not None else 1
        end = self.expr(body["end"], env)
        if not all(_num(v) for v in (start, step, end)):
            raise self.unsupported("range with non-constant bounds")
        vals = []
        x = start
        while (step > 0 and x <= end + 1e-12) or (step < 0 and x >= end - 1e-12):
            vals.append(x)
            x += step
        arr = np.empty(len(vals), dtype=object)
        for i, v in enumerate(vals):
            arr[i] = v
        return arr

    def _x_BuiltinCall(self, body: Any, env: Any) -> Value:
        fn = str(body["function"])
        args_nodes = body.get("args") or []
        lname = fn.lower()
        if lname == "der":
            return self._der(args_nodes[0], env)
        if lname in _UNSUPPORTED_BUILTINS:
            raise self.unsupported(f"built-in {lname}()", _UNSUPPORTED_BUILTINS[lname])
        args = [self.expr(a, env) for a in args_nodes]
        return _builtin(lname, args, self)

    def _x_FunctionCall(self, body: Any, env: Any) -> Value:
        fname = body["name"]["name"]
        args = [self.expr(a, env) for a in (body.get("args") or [])]
        if fname in _BUILTIN_NAMES:
            return _builtin(fname.lower(), args, self)
        fn = self.functions.get(fname)
        if fn is None:
            raise CompileError(f"call of unknown function {fname!r} in {self.model}")
        outs = self.inline(fname, fn, args)
        return outs[0]

    def _der(self, node: Any, env: Any) -> Value:
        kind, body = _kind_of(node)
        if kind != "VarRef":
            raise self.unsupported("der() of an expression", r"\bder\s*\(", "write der(x) of a variable")
        val = self._x_VarRef(body, env)
        return _elementwise(self._der_scalar, val)

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

    # ------------------------------------------------------------ functions
    def inline(self, fname: str, fn: dict[str, Any], args: list[Value]) -> list[Value]:
        self._inline_depth += 1
        if self._inline_depth > 40:
            raise self.unsupported(f"recursive function {fname!r}")
        try:
            env: dict[str, Value] = {}
            inputs = fn.get("inputs") or []
            for i, inp in enumerate(inputs):
                if i < len(args):
                    env[inp["name"]] = args[i]
                elif inp.get("default") is not None:
                    env[inp["name"]] = self.expr(inp["default"], env)
                else:
                    raise CompileError(f"call of {fname!r} in {self.model} lacks argument {inp['name']!r}")
            for loc in (fn.get("outputs") or []) + (fn.get("locals") or []):
                if loc.get("default") is not None:
                    env[loc["name"]] = self.expr(loc["default"], env)
            self._statements(fn.get("body") or [], env, fname)
            outs = []
            for out in fn.get("outputs") or []:
                if out["name"] not in env:
                    raise CompileError(f"function {fname!r} does not assign its output {out['name']!r}")
                outs.append(env[out["name"]])
            return outs
        finally:
            self._inline_depth -= 1

    def _statements(self, stmts: list[Any], env: dict[str, Value], fname: str) -> None:
        for st in stmts:
            kind, body = _kind_of(st)
            if kind == "Assignment":
                value = self.expr(body["value"], env)
                parts = body["comp"]["parts"]
                if len(parts) != 1:
                    raise self.unsupported(f"record field assignment in function {fname!r}")
                ident = parts[0]["ident"]
                subs = parts[0].get("subs") or []
                if subs:
                    idx = tuple(self._index(s) - 1 for s in subs)
                    arr = env.get(ident)
                    if not isinstance(arr, np.ndarray):
                        raise self.unsupported(f"indexed assignment to {ident!r} in function {fname!r}")
                    arr = arr.copy()
                    arr[idx] = value
                    env[ident] = arr
                else:
                    env[ident] = value
            elif kind == "If":
                self._if_statement(body, env, fname)
            elif kind == "For":
                self._for_statement(body, env, fname)
            else:
                pattern = {"While": r"\bwhile\b", "Return": r"\breturn\b", "Break": r"\bbreak\b"}.get(kind)
                raise self.unsupported(f"{kind.lower()} statement in function {fname!r}", pattern)

    def _if_statement(self, body: Any, env: dict[str, Value], fname: str) -> None:
        blocks = body.get("cond_blocks") or body.get("branches") or []
        else_block = body.get("else_block") or body.get("else_branch") or []
        conds_and_envs = []
        for blk in blocks:
            if isinstance(blk, dict):
                cond_node, stmts = blk.get("cond"), blk.get("stmts", blk.get("body", []))
            else:
                cond_node, stmts = blk
            cond = self.expr(cond_node, env)
            if _num(cond):
                if bool(cond):
                    branch_env = dict(env)
                    self._statements(stmts, branch_env, fname)
                    conds_and_envs.append((True, branch_env))
                    break
                continue
            branch_env = dict(env)
            self._statements(stmts, branch_env, fname)
            conds_and_envs.append((cond, branch_env))
        else:
            final_env = dict(env)
            self._statements(else_block or [], final_env, fname)
            conds_and_envs.append((True, final_env))
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
                    out[key] = _elementwise2(lambda x, y: ca.if_else(cond, x, y), a, b)
            merged = out
        env.clear()
        env.update(merged)

    def _for_statement(self, body: Any, env: dict[str, Value], fname: str) -> None:
        indices = body.get("indices") or []
        if len(indices) != 1:
            raise self.unsupported(f"for-loop with {len(indices)} indices in function {fname!r}")
        ident = indices[0].get("ident")
        name = ident.get("text") if isinstance(ident, dict) else ident
        rng = self.expr(indices[0]["range"], env)
        for value in rng:
            env[name] = value
            self._statements(body.get("equations") or body.get("stmts") or body.get("body") or [], env, fname)

    # ------------------------------------------------------------ translate
    def translate(self) -> ExplicitModel:
        self.check_constructs()
        self.collect_variables()
        # Real parameters: tunable (value does not depend on other parameters) or calculated.
        params, calculated, calc_eqs = [], [], []
        for sv in self.scalars.values():
            if sv.kind != "parameter":
                continue
            node = sv.binding_node
            if node is None:
                params.append(sv)
                continue
            val = self._element(sv, node)
            if _num(val) or (isinstance(val, ca.MX) and not ca.symvar(val)):
                params.append(sv)
            else:
                calculated.append(sv)
                calc_eqs.append((sv.sym - val, f"binding of parameter {sv.name}"))
        for sv in params:
            self.parameter_start(sv)
        residuals: list[tuple[ca.MX, str]] = list(calc_eqs)
        check_lost_der_equations(self.flat, self.source, self.model)
        for eq in self.flat.get("equations", []):
            origin = _origin_text(eq.get("origin"))
            val = self.expr(eq["residual"])
            for r in (val.ravel() if isinstance(val, np.ndarray) else [val]):
                if _num(r):
                    if abs(float(r)) > 0:
                        raise CompileError(f"equation {origin} in {self.model} reduces to {r} = 0")
                    continue
                residuals.append((r, origin))
        # bound continuous variables (binding equations in declarations)
        for sv in self.scalars.values():
            if sv.kind == "continuous" and sv.binding_node is not None:
                residuals.append((sv.sym - self._element(sv, sv.binding_node), f"binding of {sv.name}"))

        states = [self.scalars[n] for n in self.der_placeholders]
        state_names = set(self.der_placeholders)
        algebraics = [sv for sv in self.scalars.values() if sv.kind == "continuous" and sv.name not in state_names]
        unknowns: list[ca.MX] = [self.der_placeholders[s.name] for s in states]
        unknowns += [sv.sym for sv in algebraics] + [sv.sym for sv in calculated]
        unknown_names = [u.name() for u in unknowns]
        position = {n: i for i, n in enumerate(unknown_names)}
        incidence = []
        for r, _origin in residuals:
            incidence.append(sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position}))
        try:
            blocks = blt(incidence, len(unknowns))
        except StructuralError as exc:
            raise CompileError(self._structural_message(exc, residuals, unknown_names)) from None

        guess = {}
        for sv in algebraics + calculated:
            node = sv.start_node
            try:
                guess[sv.name] = 0.0 if node is None else self.numeric(self._element(sv, node), "start value")
            except CompileError:
                guess[sv.name] = 0.0
        assignments: list[tuple[ca.MX, ca.MX]] = []
        loop_sizes: list[int] = []
        torn_sizes: list[tuple[int, int]] = []
        self._parameter_names = {sv.name for sv in params}
        for k, block in enumerate(blocks):
            res = [residuals[i][0] for i in block.equations]
            unk = [unknowns[j] for j in block.unknowns]
            if len(unk) == 1:
                sol = _solve_scalar_linear(res[0], unk[0])
                if sol is not None:
                    assignments.append((unk[0], sol))
                    continue
            tears, solved, residual = self._tear(res, unk)
            loop_sizes.append(len(tears))
            torn_sizes.append((len(unk), len(tears)))
            if not tears:  # every equation solved explicitly in turn (cannot happen for an SCC, kept safe)
                assignments.extend(solved)
                continue
            sols = self._torn_rootfinder(k, residual, tears, solved, [guess.get(u.name(), 0.0) for u in tears])
            assignments.extend(zip(tears, sols))
            assignments.extend(solved)
        log.debug("%s: %d blocks, algebraic loops (equations, tearing variables): %s",
                  self.model, len(blocks), torn_sizes)
        # A parameter that no equation uses (e.g. one that only sets start values) would be a
        # tunable parameter with no effect: the FMU's states start from fixed numbers, so it is
        # not exported; set the state's own start value instead.
        used = {s.name() for s in ca.symvar(ca.vertcat(*[e for _, e in assignments]))} if assignments else set()
        unused = [sv.name for sv in params if sv.name not in used]
        params = [sv for sv in params if sv.name in used]
        return ExplicitModel(
            name=self.model, time=self.time, parameters=params, calculated=calculated, unused_parameters=unused,
            inputs=[sv for sv in self.scalars.values() if sv.kind == "input"],
            states=states, algebraics=algebraics, derivative=dict(self.der_placeholders),
            assignments=assignments, n_loops=len(loop_sizes), loop_sizes=loop_sizes, torn_sizes=torn_sizes,
        )

    def _tear(self, res: list[ca.MX], unk: list[ca.MX]) -> tuple[list[ca.MX], list[tuple[ca.MX, ca.MX]], list[ca.MX]]:
        """Greedy tearing of an algebraic loop.

        Repeatedly solve an equation that has one unknown left and is linear in
        it with a coefficient that depends on parameters only (never zero at run
        time by surprise); when none is left, make the unknown that appears in
        the most remaining equations a tearing variable. Returns the tearing
        variables, the explicit assignments in order, and the residual
        equations (as many as tearing variables) that the rootfinder solves.
        """
        names = [u.name() for u in unk]
        index = {n: i for i, n in enumerate(names)}
        eq_vars = [{index[s.name()] for s in ca.symvar(r) if s.name() in index} for r in res]
        known: set[int] = set()
        remaining = list(range(len(res)))
        tears: list[int] = []
        solved: list[tuple[ca.MX, ca.MX]] = []
        while remaining:
            progress = False
            for e in list(remaining):
                left = eq_vars[e] - known
                if len(left) != 1:
                    continue
                v = next(iter(left))
                sol = self._solve_with_parameter_coefficient(res[e], unk[v])
                if sol is None:
                    continue
                solved.append((unk[v], sol))
                known.add(v)
                remaining.remove(e)
                progress = True
            if progress:
                continue
            unknown = [v for v in range(len(unk)) if v not in known]
            if not unknown:
                break
            counts = {v: sum(1 for e in remaining if v in eq_vars[e]) for v in unknown}
            tear = max(unknown, key=lambda v: (counts[v], -v))
            tears.append(tear)
            known.add(tear)
        if len(remaining) != len(tears):  # pragma: no cover - counting argument guarantees equality
            raise CompileError(f"tearing of an algebraic loop in {self.model} went wrong "
                               f"({len(remaining)} residuals for {len(tears)} tearing variables)")
        return [unk[t] for t in tears], solved, [res[e] for e in remaining]

    def _solve_with_parameter_coefficient(self, res: ca.MX, v: ca.MX) -> ca.MX | None:
        jac = ca.jacobian(res, v)
        if jac.is_zero():
            return None
        if any(s.name() not in self._parameter_names for s in ca.symvar(jac)):
            return None
        r0 = ca.substitute(res, v, ca.MX(0))
        return -r0 / jac

    def _torn_rootfinder(self, k: int, residual: list[ca.MX], tears: list[ca.MX],
                         solved: list[tuple[ca.MX, ca.MX]], guess: list[float]) -> list[ca.MX]:
        """Rootfinder over the tearing variables only; the torn equations are inlined."""
        inner = list(residual)
        # express the residuals in tearing variables and outer symbols: substitute the
        # explicitly solved unknowns, latest first, so each definition sees the earlier ones
        for var, expr in reversed(solved):
            inner = ca.substitute(inner, [var], [expr])
        return self._rootfinder(k, inner, tears, guess)

    def _rootfinder(self, k: int, res: list[ca.MX], unk: list[ca.MX], guess: list[float]) -> list[ca.MX]:
        others: dict[str, ca.MX] = {}
        unk_names = {u.name() for u in unk}
        for r in res:
            for s in ca.symvar(r):
                if s.name() not in unk_names:
                    others[s.name()] = s
        other_syms = list(others.values())
        z = ca.MX.sym(f"loop{k}_z", len(unk))
        p = ca.MX.sym(f"loop{k}_p", len(other_syms))
        g = ca.substitute(
            [ca.vertcat(*res)], unk + other_syms,
            [z[i] for i in range(len(unk))] + [p[i] for i in range(len(other_syms))],
        )[0]
        rf = ca.rootfinder(
            f"loop{k}", "fast_newton", {"x": z, "p": p, "g": g},
            {"abstol": 1e-10, "max_iter": 100},
        )
        sol = rf(ca.DM(guess), ca.vertcat(*other_syms) if other_syms else ca.DM.zeros(0, 1))
        return [sol[i] for i in range(len(unk))]

    def _structural_message(self, exc: StructuralError, residuals: list[tuple[ca.MX, str]], names: list[str]) -> str:
        n_eq, n_unk = len(residuals), len(names)
        head = f"{self.model} is structurally singular: {n_eq} equations for {n_unk} unknowns"
        eqs = sorted({residuals[i][1] for i in exc.equations})[:8]
        unk = [names[j] for j in exc.unknowns][:8]
        parts = [head]
        if unk:
            parts.append("variables not determined by any equation: " + ", ".join(unk))
        if eqs and n_eq != n_unk or (eqs and unk):
            parts.append("equations with no variable left to solve for, from: " + ", ".join(eqs))
        return "; ".join(parts)


def _origin_text(origin: Any) -> str:
    kind, body = _kind_of(origin)
    if kind == "ComponentEquation":
        comp = body.get("component") or "(top level)"
        return f"of component {comp}"
    if kind == "Connection":
        return f"connect({body.get('lhs')}, {body.get('rhs')})"
    return str(kind)


def _solve_scalar_linear(res: ca.MX, v: ca.MX) -> ca.MX | None:
    jac = ca.jacobian(res, v)
    if ca.depends_on(jac, v):
        return None
    if jac.is_zero():
        return None
    r0 = ca.substitute(res, v, ca.MX(0))
    return -r0 / jac


_BUILTIN_NAMES = {
    "abs", "sqrt", "exp", "log", "log10", "sin", "cos", "tan", "asin", "acos", "atan", "atan2",
    "sinh", "cosh", "tanh", "min", "max", "sign", "floor", "ceil", "noEvent", "smooth", "homotopy",
    "semiLinear", "sum", "product", "integer", "div", "mod", "rem",
}


def _elementwise(fn: Callable[[Any], Any], a: Value) -> Value:
    if isinstance(a, np.ndarray):
        out = np.empty(a.shape, dtype=object)
        for idx in np.ndindex(a.shape):
            out[idx] = fn(a[idx])
        return out
    return fn(a)


def _elementwise2(fn: Callable[[Any, Any], Any], a: Value, b: Value) -> Value:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        shape = a.shape if isinstance(a, np.ndarray) else b.shape
        out = np.empty(shape, dtype=object)
        for idx in np.ndindex(shape):
            out[idx] = fn(a[idx] if isinstance(a, np.ndarray) else a, b[idx] if isinstance(b, np.ndarray) else b)
        return out
    return fn(a, b)


def _not(a: Any) -> Any:
    return (not a) if _num(a) else ca.logic_not(a)


def _binary(op: str, a: Value, b: Value, tr: FlatTranslator) -> Value:
    o = op.lower()
    if o.startswith("dot") or o.startswith("elem"):
        o = o.replace("dot", "").replace("elem", "")
    both_num = _num(a) and _num(b)
    if o in ("add", "plus"):
        return _elementwise2(lambda x, y: x + y, a, b)
    if o in ("sub", "minus"):
        return _elementwise2(lambda x, y: x - y, a, b)
    if o in ("mul", "times"):
        if isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.ndim == 1 and b.ndim == 1:
            return sum((a[i] * b[i] for i in range(len(a))), 0.0)
        return _elementwise2(lambda x, y: x * y, a, b)
    if o == "div":
        return _elementwise2(lambda x, y: x / y, a, b)
    if o in ("exp", "pow", "power"):
        def power(x: Any, y: Any) -> Any:
            if _num(x) and _num(y):
                return float(x) ** float(y)
            if _num(y) and float(y) == 2.0:
                return x * x
            if _num(y) and float(y).is_integer() and 0 < abs(float(y)) <= 8:
                return ca.constpow(x, float(y))
            return ca.power(x, y)
        return _elementwise2(power, a, b)
    cmp = {"lt": "<", "le": "<=", "gt": ">", "ge": ">=", "eq": "==", "neq": "!=", "ne": "!="}
    if o in cmp:
        if both_num:
            return {"<": a < b, "<=": a <= b, ">": a > b, ">=": a >= b, "==": a == b, "!=": a != b}[cmp[o]]
        x, y = a, b
        return {"<": x < y, "<=": x <= y, ">": x > y, ">=": x >= y, "==": x == y, "!=": x != y}[cmp[o]]
    if o == "and":
        if _num(a) and not a:
            return False
        if _num(b) and not b:
            return False
        if _num(a):
            return b
        if _num(b):
            return a
        return ca.logic_and(a, b)
    if o == "or":
        if (_num(a) and a) or (_num(b) and b):
            return True
        if _num(a):
            return b
        if _num(b):
            return a
        return ca.logic_or(a, b)
    raise tr.unsupported(f"binary operator {op!r}")


def _fold(values: list[Value]) -> list[Value]:
    out: list[Value] = []
    for v in values:
        if isinstance(v, np.ndarray):
            out.extend(v.ravel().tolist())
        else:
            out.append(v)
    return out


def _builtin(name: str, args: list[Value], tr: FlatTranslator) -> Value:
    def unary(f_num: Callable[[float], float], f_sym: Callable[[Any], Any]) -> Value:
        return _elementwise(lambda a: f_num(float(a)) if _num(a) else f_sym(a), args[0])

    n = name.lower()
    simple = {
        "sqrt": (math.sqrt, ca.sqrt), "exp": (math.exp, ca.exp), "log": (math.log, ca.log),
        "log10": (math.log10, ca.log10), "sin": (math.sin, ca.sin), "cos": (math.cos, ca.cos),
        "tan": (math.tan, ca.tan), "asin": (math.asin, ca.asin), "acos": (math.acos, ca.acos),
        "atan": (math.atan, ca.atan), "sinh": (math.sinh, ca.sinh), "cosh": (math.cosh, ca.cosh),
        "tanh": (math.tanh, ca.tanh), "abs": (abs, ca.fabs), "floor": (math.floor, ca.floor),
        "ceil": (math.ceil, ca.ceil), "sign": (lambda x: float(np.sign(x)), ca.sign),
    }
    if n in simple:
        return unary(*simple[n])
    if n == "integer":
        return unary(lambda x: float(math.floor(x)), ca.floor)
    if n in ("noevent",):
        return args[0]
    if n == "smooth":
        return args[1]
    if n == "homotopy":
        return args[0]
    if n == "semilinear":
        x, a, b = args
        return ca.if_else(x >= 0, a * x, b * x) if not _num(x) else (a * x if x >= 0 else b * x)
    if n == "atan2":
        return _elementwise2(lambda y, x: math.atan2(y, x) if _num(y) and _num(x) else ca.atan2(y, x), args[0], args[1])
    if n in ("min", "max"):
        vals = _fold(args) if len(args) == 1 else args
        if len(vals) == 2 and (isinstance(vals[0], np.ndarray) or isinstance(vals[1], np.ndarray)):
            fn = ca.fmin if n == "min" else ca.fmax
            return _elementwise2(lambda x, y: fn(x, y), vals[0], vals[1])
        acc = vals[0]
        for v in vals[1:]:
            if _num(acc) and _num(v):
                acc = min(acc, v) if n == "min" else max(acc, v)
            else:
                acc = ca.fmin(acc, v) if n == "min" else ca.fmax(acc, v)
        return acc
    if n == "sum":
        return sum(_fold(args), 0.0)
    if n == "product":
        acc: Value = 1.0
        for v in _fold(args):
            acc = acc * v
        return acc
    if n in ("div", "mod", "rem"):
        a, b = args
        if _num(a) and _num(b):
            if n == "div":
                return float(math.trunc(a / b))
            if n == "mod":
                return a - math.floor(a / b) * b
            return a - math.trunc(a / b) * b
        if n == "mod":
            return a - ca.floor(a / b) * b
        raise tr.unsupported(f"built-in {n}() of a variable")
    if n == "size":
        raise tr.unsupported("size() left unevaluated")
    raise tr.unsupported(f"built-in {n}()", rf"\b{n}\s*\(")


def _ref_text(node: Any) -> str:
    """``x[3,1]`` for a flat variable reference with constant subscripts (best effort)."""
    kind, body = _kind_of(node)
    if kind != "VarRef" or not isinstance(body, dict):
        return "?"
    subs = []
    for sub in body.get("subscripts") or []:
        skind, sbody = _kind_of(sub)
        subs.append(str(sbody.get("value")) if skind == "Index" and isinstance(sbody, dict) else ":")
    return str(body["name"]["name"]) + (f"[{','.join(subs)}]" if subs else "")


def check_lost_der_equations(flat: dict[str, Any], source: ModelicaSource, model: str) -> None:
    """Refuse a flat model in which the front end lost the right-hand side of a ``der`` equation.

    rumoca 0.10.2 flattens ``der(x[i]) = a[i] - x[i]`` in a for-loop into
    ``der(x[3]) - 0.0`` for some iterations (the embedded backend writes such
    equations so that rumoca gets them right, :mod:`.rewrite`; this is the safety
    net). The signature: a residual ``der(v) - literal`` whose literal carries the
    equation's own span, and the source text at that span is not that literal (it
    is the loop's iterator). A literal the user wrote, ``der(x[i]) = 0``, spans its
    own text and passes.

    Raises
    ------
    CompileError
        Naming the model, each equation lost (variable) and the line of its loop.
    """
    suspects = []
    for eq in flat.get("equations") or []:
        kind, body = _kind_of(eq.get("residual"))
        if kind != "Binary" or not isinstance(body, dict) or body.get("op") != "Sub":
            continue
        lkind, lhs = _kind_of(body.get("lhs"))
        while lkind == "Parenthesized" and isinstance(lhs, dict):
            lkind, lhs = _kind_of(lhs.get("inner"))
        rkind, rhs = _kind_of(body.get("rhs"))
        if lkind != "BuiltinCall" or str(lhs.get("function", "")).lower() != "der" or rkind != "Literal":
            continue
        span = eq.get("span")
        if isinstance(span, dict) and isinstance(span.get("start"), int) and rhs.get("span") == span:
            suspects.append((_ref_text((lhs.get("args") or [None])[0]), rhs, span))
    if not suspects:
        return
    from .source import BOM

    files = model_files(source, model)
    known = span_sources(flat, files)
    lost = []
    for var, lit, span in suspects:
        candidates = [known[span["source"]]] if span.get("source") in known else list(files)
        text, loc = None, None
        for file in candidates:
            try:
                data = file.read_bytes()
            except OSError:
                continue
            data = data[3:] if data.startswith(BOM) else data
            if span.get("end", span["start"]) <= len(data):
                text = data[span["start"]:span.get("end", span["start"])].decode("utf-8", "replace").strip()
                loc = Location(file, data.count(b"\n", 0, span["start"]) + 1)
                break
        value = _kind_of(lit.get("value"))[1]
        try:
            genuine = text is not None and float(text) == float(value)
        except (TypeError, ValueError):
            genuine = False
        if not genuine:
            lost.append(f"der({var}) = ... came back as der({var}) = {value}"
                        + (f" (for-loop at {loc})" if loc else ""))
    if lost:
        shown = "; ".join(lost[:8]) + (f"; and {len(lost) - 8} more" if len(lost) > 8 else "")
        raise CompileError(
            f"the Modelica front end (rumoca) lost the right-hand side of {len(lost)} equation(s) of "
            f"{model}: {shown}. This is a rumoca bug with der(...) = ... in for-loops; write the left-hand "
            "side in parentheses, (der(x[i])) = ..., or use --backend openmodelica")
