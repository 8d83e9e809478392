"""From rumoca's flattened model to an explicit, causalised CasADi model.

rumoca (pinned; its JSON schema is internal) parses, resolves and flattens the
Modelica source. This module reads the flat model (``Model.to_dict("flat")``):

* array variables are scalarised (``Th[3]``), structural parameters (Integer,
  Boolean) and constants are evaluated, every Real parameter becomes a symbol;
* expressions become CasADi ``MX`` expressions; Modelica functions are inlined
  symbolically (assignments, if-statements, for-loops over constant ranges);
* arrays keep their Modelica meaning (:mod:`.arrays`): matrix and vector
  products, matrix powers, element-wise operators, slices, array constructors,
  comprehensions and reductions; sizes that do not fit and constants a
  function cannot take (``sqrt(-1)``, ``1/0``) are errors naming the
  expression and its line;
* modifications that rumoca is known to lose are refused before they give
  wrong numbers (:mod:`.modifiers`);
* the equations are matched to their unknowns and sorted into blocks
  (:mod:`.causalize`): a scalar block linear in its unknown is solved
  symbolically, anything else goes to a Newton rootfinder.

Conditions (``if`` expressions, ``min``/``max``/``abs``) are evaluated as they
stand at each right-hand-side call: there is no event detection, so the
integrator crosses a switch like any other steep change. ``noEvent`` and
``smooth`` are therefore accepted and change nothing.

``assert(condition, message, level)`` in equation sections and in the
algorithm bodies of inlined functions becomes an :class:`Assertion` (a
condition in the model's variables, its message and level; an assert inside
an ``if`` branch of a function holds only where the branch is taken). The
exported FMU evaluates every condition when it leaves initialisation mode,
after each event (e.g. a parameter change) and at each completed integrator
step: a failing error-level assert makes the call return ``fmi3Error`` after
logging ``assert failed at t = ... s: message`` (category ``assert``); a
warning-level one logs a warning once per violation and the run goes on.

``initial equation`` sections are solved when the FMU leaves initialisation
mode (:class:`InitialSystem`): the unknowns are the states that are not
``fixed = true`` and the parameters declared ``fixed = false``; the equations
are the initial equations, in which ``der(x)`` and the algebraic variables are
replaced by their causalised expressions, plus ``x = start`` for states with
``fixed = true``. If there are fewer equations than unknowns, states that no
initial equation mentions keep their start values. The system is solved by
a Newton rootfinder compiled into the FMU, from the start values as guesses
and with the parameters as the user set them. Models without initial
equations are exported exactly as before.

Anything else (when-clauses, algorithm sections in models, discrete variables,
``pre``/``edge``/``sample``/``reinit``/``initial()``/``terminal()``, initial
algorithm sections, external functions) raises
:class:`UnsupportedConstructError` naming the construct and where it stands.
"""
from __future__ import annotations

import itertools
import logging
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ..errors import CompileError, UnsupportedConstructError
from . import arrays as arr
from .arrays import ArrayError
from .causalize import StructuralError, blt
from .modifiers import modifier_check
from .semantics import check_flat
from .library import locate, model_files
from .source import (Location, ModelicaSource, class_extent, read_text, span_location,
                     span_sources, strip_comments)

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


@dataclass(frozen=True)
class Assertion:
    """One ``assert(condition, message, level)`` of the model or of an inlined function."""

    condition: ca.MX  # 1 where the assert holds, 0 where it fails
    message: str
    level: str  # "error" | "warning"
    origin: str


@dataclass(frozen=True)
class InitialSystem:
    """The initialisation problem solved when the FMU leaves initialisation mode.

    ``residual`` (one entry per equation) is expressed in ``unknowns`` (free
    states, then ``fixed = false`` parameters) and ``knowns`` (time,
    parameters, inputs, fixed states); no algebraic variable or derivative
    is left in it.
    """

    unknowns: list[ca.MX]
    knowns: list[ca.MX]
    residual: list[ca.MX]
    free_states: list[str]
    computed_parameters: list[str]
    origins: list[str]


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
    asserts: list[Assertion] = field(default_factory=list)
    initial: InitialSystem | None = None


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

    def __init__(self, flat: dict[str, Any], source: ModelicaSource, model: str,
                 libraries: tuple[Path, ...] = ()):
        self.flat = flat
        self.source = source
        self.model = model
        self.libraries = tuple(libraries)
        self.types = flat.get("effective_types", {})
        self.functions = flat.get("functions", {}) or {}
        self.vars: dict[str, list[ScalarVar]] = {}
        self.scalars: dict[str, ScalarVar] = {}
        self.dims: dict[str, tuple[int, ...]] = {}
        self.time = ca.MX.sym("time")
        self.der_placeholders: dict[str, ca.MX] = {}
        self._evaluating: set[str] = set()
        self._inline_depth = 0
        self.asserts: list[Assertion] = []
        self._guards: list[Any] = []  # conditions of the function if-branches being inlined
        self._span: dict[str, Any] | None = None  # span of the expression being translated (for errors)
        self._files: tuple[Path, ...] | None = None
        self._sources: dict[int, Path] | None = None
        self._text_cache: dict[Path, str] = {}

    # ------------------------------------------------------------------ errors
    def location(self, pattern: str | None = None, span: dict[str, Any] | None = None) -> list[Location]:
        """Where a construct stands: the model's own file (or a class it uses) and the line.

        From the front end's *span* (default: the expression being translated) when it
        matches *pattern*; else from a search for *pattern* restricted to the files of
        the classes the model uses (:func:`.source.locate`), never other files of the package.
        """
        if self._files is None:
            self._files = model_files(self.source, self.model, libraries=self.libraries)
            self._sources = span_sources(self.flat, self._files)
        span = span if span is not None else self._span
        if span is not None:
            known = self._sources.get(span.get("source")) if self._sources else None
            files = (known,) if known is not None else self._files
            loc = span_location(span, files, pattern)
            if loc is not None:
                return [loc]
        if pattern:
            locs = locate(self.source, self.model, pattern, libraries=self.libraries)
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
        for fname, fn in self.functions.items():
            ext = fn.get("external")
            if ext and _builtin_external(ext) is None:
                raise self.unsupported(f"external function {fname!r}", r"\bexternal\b")

    # ------------------------------------------------------------ variables
    def _type_of(self, v: dict[str, Any]) -> int:
        t = self.types.get(str(v.get("type_id")))
        if t is None:
            return REAL
        return int(t.get("canonical_type", REAL))

    def check_modifiers(self) -> None:
        """Refuse models whose modifications rumoca 0.10.2 loses (see :mod:`.modifiers`)."""
        lost = modifier_check(self.source, self.libraries).check(self.model)
        if lost:
            log.warning("%s: bounds or units lost by the front end (no effect on values): %s",
                        self.model, "; ".join(lost))

    def collect_variables(self) -> None:
        # values are only as good as the modifications the front end kept
        self.check_modifiers()
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
            base = sv.name.split("[", 1)[0] if sv.index else sv.name
            expected = self.dims.get(base, ())
            if val.shape != expected:
                raise CompileError(
                    f"value of size {arr.size_text(val.shape)} given to {base!r} of size "
                    f"{arr.size_text(expected)} in {self.model}: `{expression_text(node)}`"
                )
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
                return arr.subscript(val, [self._subscript(s, val, k, env) for k, s in enumerate(subs)], repr(name))
            return val
        if name == "time":
            return self.time
        if name not in self.vars:
            ordinal = (self.flat.get("enum_literal_ordinals") or {}).get(name)
            if ordinal is not None and not subs:  # an enumeration literal is its ordinal (MLS 4.9.5)
                return int(ordinal)
            # component_ref names of array elements of components come as "a[2].b"
            raise CompileError(f"unknown variable {name!r} referenced in {self.model}")
        scalars = self.vars[name]
        dims = self.dims[name]
        picks: list[Value] = []
        if subs:
            if len(subs) > len(dims):
                raise CompileError(f"{len(subs)} subscripts for {name!r} of size {arr.size_text(dims)} "
                                   f"in {self.model}")
            # ``end`` comes as size(name, k): evaluate it on a placeholder of the right size
            shape_only = arr.new(dims)
            picks = [self._subscript(s, shape_only, k, env) for k, s in enumerate(subs)]
        if picks and len(picks) == len(dims) and all(isinstance(p, int) for p in picks):
            sname = name + "[" + ",".join(str(i) for i in picks) + "]"
            if sname not in self.scalars:
                raise CompileError(f"index {picks} out of range for {name!r} of size "
                                   f"{arr.size_text(dims)} in {self.model}")
            return self._scalar_value(self.scalars[sname])
        if dims:
            full = arr.new(dims)
            for sv in scalars:
                full[tuple(i - 1 for i in sv.index)] = self._scalar_value(sv)
        else:
            full = self._scalar_value(scalars[0])
        if subs:
            return arr.subscript(full, picks, repr(name))
        return full

    def _scalar_value(self, sv: ScalarVar) -> Value:
        if sv.kind in ("structural", "constant"):
            return self.structural_value(sv)
        return sv.sym

    def _subscript(self, sub: Any, value: Value, k: int, env: dict[str, Value] | None) -> Value:
        """One subscript: an Integer, a vector of Integers, or None for ``:``.

        ``end`` comes from the flat model as ``size(a, k)`` of the array itself.
        """
        kind, body = _kind_of(sub)
        if kind == "Index":
            return int(body["value"])
        if kind == "Colon":
            return None
        if kind == "Expr":
            val = self.expr(body["expr"], env)
            if arr.is_array(val):
                if not all(_num(v) for v in val.ravel()):
                    raise CompileError(f"non-constant array subscript `{expression_text(body['expr'])}` "
                                       f"in {self.model}")
                return val
            if not _num(val):
                raise self.unsupported(
                    f"subscript with a variable index `{expression_text(body['expr'])}`",
                    detail="indices must be parameters or constants",
                )
            return int(round(float(val)))
        raise self.unsupported(f"array subscript {kind!r}")

    # ------------------------------------------------------------ expressions
    def expr(self, node: Any, env: dict[str, Value] | None = None) -> Value:
        kind, body = _kind_of(node)
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
            hint = _span_hint(body)
            locs = self.location(rf"\s*{re.escape(hint)}\b" if hint else None,
                                 span if isinstance(span, dict) else None)
            where = f" at {locs[0]}" if locs else ""
            raise CompileError(f"{exc} in `{expression_text(node)}` in {self.model}{where}") from None

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
        if _kind_of(body["lhs"])[0] == "Tuple":
            return self._tuple_equation(body, env)
        lhs = self.expr(body["lhs"], env)
        rhs = self.expr(body["rhs"], env)
        return _binary(str(op), lhs, rhs, self)

    def _tuple_equation(self, body: Any, env: Any) -> Value:
        """``(a, , c) = f(x)``: one residual per output that is not omitted, flattened."""
        kind, call = _kind_of(body["rhs"])
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
            if _kind_of(target)[0] == "Empty":
                continue
            residuals.extend(arr.elements([_binary("Sub", self.expr(target, env), out, self)]))
        return arr.from_list(residuals)

    def _x_Index(self, body: Any, env: Any) -> Value:
        """A subscripted expression, e.g. ``f(x)[2]`` or an array input ``A[i]`` inside a function."""
        base = self.expr(body["base"], env)
        subs = body.get("subscripts") or []
        return arr.subscript(base, [self._subscript(s, base, k, env) for k, s in enumerate(subs)],
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
            return arr.map1(_not, arg)
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
        if not all(_num(v) for v in (start, step, end)):
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
        if lname in _UNSUPPORTED_BUILTINS:
            raise self.unsupported(f"built-in {lname}()", _UNSUPPORTED_BUILTINS[lname])
        args = [self.expr(a, env) for a in args_nodes]
        return _builtin(lname, args, self)

    def _x_FunctionCall(self, body: Any, env: Any) -> Value:
        fname = body["name"]["name"]
        args = [self.expr(a, env) for a in (body.get("args") or [])]
        if fname in _BUILTIN_NAMES or (fname.lower() in _ARRAY_BUILTINS and fname not in self.functions):
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

    # ------------------------------------------------------------ functions
    def inline(self, fname: str, fn: dict[str, Any], args: list[Value]) -> list[Value]:
        ext = fn.get("external")
        builtin = _builtin_external(ext) if ext else None
        if builtin is not None:  # external "builtin": the language's own function (Modelica.Math.sin, ...)
            return self._builtin_external(fname, fn, ext, builtin, args)
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

    def _builtin_external(self, fname: str, fn: dict[str, Any], ext: dict[str, Any], builtin: str,
                          args: list[Value]) -> list[Value]:
        """``external "builtin" y = sin(u)``: the built-in on the external call's arguments, which
        name the function's inputs (given, or their defaults)."""
        env: dict[str, Value] = {}
        for i, inp in enumerate(fn.get("inputs") or []):
            if i < len(args):
                env[inp["name"]] = args[i]
            elif inp.get("default") is not None:
                env[inp["name"]] = self.expr(inp["default"], env)
            else:
                raise CompileError(f"call of {fname!r} in {self.model} lacks argument {inp['name']!r}")
        call_args = [self.expr(a, env) for a in ext.get("args") or []]
        value = _builtin(builtin, call_args, self)
        outs = [o["name"] for o in fn.get("outputs") or []]
        if len(outs) != 1 or (ext.get("output_name") not in (None, outs[0])):
            raise self.unsupported(f"external \"builtin\" function {fname!r} with other than one output "
                                   "returned by the call", r"\bexternal\b")
        return [value]

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
                    target = env.get(ident)
                    if not isinstance(target, np.ndarray):
                        raise self.unsupported(f"indexed assignment to {ident!r} in function {fname!r}")
                    picks = [self._subscript(sb, target, k, env) for k, sb in enumerate(subs)]
                    if len(picks) != target.ndim:
                        raise CompileError(f"assignment to {ident!r} in function {fname!r} with {len(picks)} "
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
                                               f"to {ident!r} in function {fname!r}")
                    target = target.copy()
                    try:
                        target[np.ix_(*[range(target.shape[k]) if p is None else
                                        ([i] if isinstance(i, int) else i) for k, (p, i) in
                                        enumerate(zip(picks, index))])] = (
                            np.asarray(value, dtype=object).reshape(
                                [target.shape[k] if p is None else (len(i) if isinstance(i, list) else 1)
                                 for k, (p, i) in enumerate(zip(picks, index))])
                            if arr.is_array(value) else value)
                    except ValueError:
                        raise CompileError(f"assignment of a value of size {arr.size_text(arr.shape(value))} "
                                           f"to a part of {ident!r} in function {fname!r} that does not "
                                           "have that size") from None
                    env[ident] = target
                else:
                    env[ident] = value
            elif kind == "If":
                self._if_statement(body, env, fname)
            elif kind == "For":
                self._for_statement(body, env, fname)
            elif kind == "Assert":
                self.add_assert(body, env, f"function {fname}")
            else:
                pattern = {"While": r"\bwhile\b", "Return": r"\breturn\b", "Break": r"\bbreak\b"}.get(kind)
                raise self.unsupported(f"{kind.lower()} statement in function {fname!r}", pattern)

    def _if_statement(self, body: Any, env: dict[str, Value], fname: str) -> None:
        blocks = body.get("cond_blocks") or body.get("branches") or []
        else_block = body.get("else_block") or body.get("else_branch") or []
        conds_and_envs = []
        prior: list[Any] = []  # symbolic conditions of the branches before (for asserts in branches)
        for blk in blocks:
            if isinstance(blk, dict):
                cond_node, stmts = blk.get("cond"), blk.get("stmts", blk.get("body", []))
            else:
                cond_node, stmts = blk
            cond = self.expr(cond_node, env)
            if _num(cond):
                if bool(cond):
                    branch_env = dict(env)
                    self._guarded(_branch_guard(None, prior), stmts, branch_env, fname)
                    conds_and_envs.append((True, branch_env))
                    break
                continue
            branch_env = dict(env)
            self._guarded(_branch_guard(cond, prior), stmts, branch_env, fname)
            prior.append(cond)
            conds_and_envs.append((cond, branch_env))
        else:
            final_env = dict(env)
            self._guarded(_branch_guard(None, prior), else_block or [], final_env, fname)
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
        cond = self.expr(body["condition"], env)
        if isinstance(cond, np.ndarray):
            raise CompileError(f"the condition of assert({message!r}) in {origin} of {self.model} is an array")
        if _num(cond) and not isinstance(cond, (bool, np.bool_)):
            raise CompileError(f"the condition of assert({message!r}) in {origin} of {self.model} is the "
                               f"number {cond!r}, not a Boolean")
        level = "error"
        if body.get("level") is not None:
            lv = self.expr(body["level"], env)  # AssertionLevel.warning = 1, error = 2
            if not _num(lv):  # rumoca already refuses this (MLS 8.3.7); kept as a clear error
                raise CompileError(f"the level of assert({message!r}) in {origin} of {self.model} "
                                   "is not a constant")
            level = "warning" if int(lv) == 1 else "error"
        self._record_assert(cond, message, level, origin)

    def _record_assert(self, cond: Any, message: str, level: str, origin: str) -> None:
        for guard in self._guards:  # an assert in a function's if-branch only counts where it is taken
            cond = ca.logic_or(_not(guard), cond) if not _num(cond) or not bool(cond) else cond
        if _num(cond):
            cond = ca.MX(1.0 if bool(cond) else 0.0)
        elif not isinstance(cond, ca.MX):
            cond = ca.MX(cond)
        self.asserts.append(Assertion(condition=ca.if_else(cond, 1.0, 0.0), message=message,
                                      level=level, origin=origin))

    def _message_text(self, node: Any, env: dict[str, Value] | None) -> str:
        """The text of an assert message: literals and constant ``String(...)`` parts; others as ``<...>``."""
        kind, body = _kind_of(node)
        if node is None:
            return "assertion failed"
        if kind == "Literal":
            val = body.get("value") or {}
            if isinstance(val, dict) and "String" in val:
                return str(val["String"])
            raise CompileError(f"the message of an assert in {self.model} is {_literal_text(val)}, not a String")
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
                if _num(val):
                    return f"{float(val):g}" if not isinstance(val, (bool, np.bool_)) else str(bool(val)).lower()
        except CompileError:
            pass
        return "<...>"

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
        check_flat(self.flat, self.model, self.location)  # constants: bound, to constant expressions
        self.collect_variables()
        # Real parameters: tunable (value does not depend on other parameters) or calculated.
        params, calculated, calc_eqs = [], [], []
        computed: list[ScalarVar] = []  # parameters with fixed = false, solved at initialisation
        init_residuals: list[tuple[ca.MX, str]] = []
        for sv in self.scalars.values():
            if sv.kind != "parameter":
                continue
            node = sv.binding_node
            if sv.fixed is False:
                params.append(sv)
                computed.append(sv)
                if node is not None:  # the binding of a fixed = false parameter is an initial equation
                    init_residuals.append((sv.sym - self._element(sv, node), f"binding of parameter {sv.name}"))
                continue
            if node is None:
                params.append(sv)
                continue
            val = self._element(sv, node)
            if _num(val) or (isinstance(val, ca.MX) and not ca.symvar(val)):
                params.append(sv)
            else:
                calculated.append(sv)
                calc_eqs.append((sv.sym - val, f"binding of parameter {sv.name}"))
        for sv in computed:  # the start value is the guess; the binding (if any) is an initial equation
            sv.value = 0.0 if sv.start_node is None else self.numeric(
                self._element(sv, sv.start_node), f"start value of parameter {sv.name!r}")
        for sv in params:
            self.parameter_start(sv)
        residuals: list[tuple[ca.MX, str]] = list(calc_eqs)
        check_lost_der_equations(self.flat, self.source, self.model, self.libraries)
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

        for a in self.flat.get("assert_equations") or []:
            self.add_assert(a, None, f"equation {self._where(a.get('origin'))}")
        for a in self.flat.get("initial_assert_equations") or []:
            self.add_assert(a, None, f"initial equation {self._where(a.get('origin'))}")

        states = [self.scalars[n] for n in self.der_placeholders]
        state_names = set(self.der_placeholders)
        for eq in self.flat.get("initial_equations") or []:
            origin = f"initial equation {self._where(eq.get('origin'))}"
            val = self.expr(eq["residual"])
            for r in (val.ravel() if isinstance(val, np.ndarray) else [val]):
                if _num(r):
                    if abs(float(r)) > 0:
                        raise CompileError(f"{origin} in {self.model} reduces to {r} = 0")
                    continue
                init_residuals.append((r, origin))
        extra = [n for n in self.der_placeholders if n not in state_names]
        if extra:
            raise self.unsupported(
                f"der({extra[0]}) in an initial equation, where {extra[0]} is not a state "
                "(no equation of the model differentiates it)", r"\binitial\s+equation\b")
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
        initial = None
        if init_residuals or computed:
            initial = self._initial_system(init_residuals, states, computed, assignments)
        asserts = self._unique_asserts()
        exprs = [e for _, e in assignments] + [a.condition for a in asserts]
        if initial is not None:
            exprs += initial.residual
        used = {s.name() for s in ca.symvar(ca.vertcat(*exprs))} if exprs else set()
        used |= {sv.name for sv in computed}
        unused = [sv.name for sv in params if sv.name not in used]
        params = [sv for sv in params if sv.name in used]
        return ExplicitModel(
            asserts=asserts, initial=initial,
            name=self.model, time=self.time, parameters=params, calculated=calculated, unused_parameters=unused,
            inputs=[sv for sv in self.scalars.values() if sv.kind == "input"],
            states=states, algebraics=algebraics, derivative=dict(self.der_placeholders),
            assignments=assignments, n_loops=len(loop_sizes), loop_sizes=loop_sizes, torn_sizes=torn_sizes,
        )

    def _where(self, origin: Any) -> str:
        text = _origin_text(origin)
        return f"of {self.model}" if text == "of component (top level)" else text

    def _unique_asserts(self) -> list[Assertion]:
        """The asserts, each once (a function inlined twice with the same arguments asserts once)."""
        seen: set[tuple[str, str, str]] = set()
        out = []
        for a in self.asserts:
            key = (a.message, a.level, str(a.condition))
            if key not in seen:
                seen.add(key)
                out.append(a)
        return out

    def _initial_system(self, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar],
                        computed: list[ScalarVar], assignments: list[tuple[ca.MX, ca.MX]]) -> InitialSystem:
        """Build the initialisation problem (see the module docstring)."""
        mentioned: set[str] = set()
        for r, _ in residuals:
            for sym in ca.symvar(r):
                name = sym.name()
                mentioned.add(name[4:-1] if name.startswith("der(") and name.endswith(")") else name)
        free = [s for s in states if s.fixed is not True]
        if len(residuals) < len(free) + len(computed):
            kept = []
            for s in list(free):
                if len(residuals) >= len(free) + len(computed):
                    break
                if s.name not in mentioned:
                    free.remove(s)
                    kept.append(s.name)
            if kept:
                log.info("%s: states kept at their start values at initialisation (no initial equation "
                         "for them): %s", self.model, ", ".join(kept))
        n_unknowns = len(free) + len(computed)
        if len(residuals) != n_unknowns:
            what = []
            if free:
                what.append("states " + ", ".join(s.name for s in free))
            if computed:
                what.append("parameters with fixed = false " + ", ".join(s.name for s in computed))
            raise CompileError(
                f"the initialisation problem of {self.model} has {len(residuals)} equations for {n_unknowns} "
                f"unknowns ({'; '.join(what) or 'none'}); "
                + ("add initial equations or set fixed = true on start values"
                   if len(residuals) < n_unknowns else
                   "remove initial equations, or fixed = true from the start values they conflict with")
            )
        exprs = [r for r, _ in residuals]
        # replace derivatives and algebraic variables by their causalised expressions, latest first
        for var, val in reversed(assignments):
            if any(ca.depends_on(e, var) for e in exprs):
                exprs = ca.substitute(exprs, [var], [val])
        unknowns = [s.sym for s in free] + [s.sym for s in computed]
        unknown_names = [u.name() for u in unknowns]
        position = {n: i for i, n in enumerate(unknown_names)}
        knowns: dict[str, ca.MX] = {}
        for e in exprs:
            for sym in ca.symvar(e):
                if sym.name() not in position:
                    knowns.setdefault(sym.name(), sym)
        incidence = [sorted({position[s.name()] for s in ca.symvar(e) if s.name() in position}) for e in exprs]
        try:
            blt(incidence, len(unknowns))
        except StructuralError as exc:
            eqs = sorted({residuals[i][1] for i in exc.equations})[:8]
            unk = [unknown_names[j] for j in exc.unknowns][:8]
            raise CompileError(
                f"the initialisation problem of {self.model} is structurally singular"
                + (f"; not determined by the initial equations: {', '.join(unk)}" if unk else "")
                + (f"; equations with no unknown left, from: {', '.join(eqs)}" if eqs else "")
            ) from None
        return InitialSystem(
            unknowns=unknowns, knowns=[knowns[n] for n in sorted(knowns)], residual=list(exprs),
            free_states=[s.name for s in free], computed_parameters=[s.name for s in computed],
            origins=[o for _, o in residuals],
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
        # a coefficient that is zero at the parameters' values (e.g. a zero entry of a parameter
        # matrix in A*y = b) cannot be divided by
        if abs(self.numeric(jac, "coefficient in an algebraic loop")) < 1e-12:
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

    def _declared_at(self, scalar: str) -> str:
        """``b.c.e (b declared at file:line)``: a flat variable and where the model's own class
        declares its top-level component (and, if elsewhere, where the variable itself is)."""
        base = scalar.split("[", 1)[0]
        head = re.split(r"[.\[]", base, maxsplit=1)[0]
        own = locate(self.source, self.model, rf"(?<![\w.]){re.escape(head)}\b(?!\s*\()", limit=1, own=True,
                     libraries=self.libraries)
        var = (self.flat.get("variables") or {}).get(base) or {}
        leaf = base.rsplit(".", 1)[-1]
        decl = self.location(rf"(?:[\w.]+\s+)+{re.escape(leaf)}\b", span=var.get("source_span")) if var else []
        where = [f"{head} declared at {own[0]}"] if own else []
        if decl and (not own or str(decl[0]) != str(own[0])):
            where.append(f"{base} at {decl[0]}")
        return f"{scalar} ({'; '.join(where)})" if where else scalar

    def _equation_at(self, origin: str) -> str:
        """An equation's origin text, with the line of the ``connect`` of the model's own class it
        comes from (``connect(a.c.e, b.c.e)`` comes from ``connect(a.c, b.c)``)."""
        conn = re.fullmatch(r"connect\((.+), (.+)\)", origin)
        extent = class_extent(self.source, self.model) if conn else None
        if conn is None or extent is None:
            return origin
        file, first, last = extent

        def within(full: str, part: str) -> bool:
            return full == part or full.startswith(part + ".") or full.startswith(part + "[")

        lines = strip_comments(read_text(file)).splitlines()
        code = "\n".join(lines[first - 1:last])
        for m in re.finditer(r"\bconnect\s*\(\s*([\w.\[\], ]+?)\s*,\s*([\w.\[\]]+)\s*\)", code):
            a, b = (re.sub(r"\s+", "", g) for g in m.groups())
            lhs, rhs = conn.groups()
            if (within(lhs, a) and within(rhs, b)) or (within(lhs, b) and within(rhs, a)):
                return f"{origin} at {file}:{first + code.count(chr(10), 0, m.start())}"
        return origin

    def _structural_message(self, exc: StructuralError, residuals: list[tuple[ca.MX, str]], names: list[str]) -> str:
        n_eq, n_unk = len(residuals), len(names)
        head = f"{self.model} is structurally singular: {n_eq} equations for {n_unk} unknowns"
        eqs = sorted({residuals[i][1] for i in exc.equations})[:8]
        unk = [names[j] for j in exc.unknowns][:8]
        parts = [head]
        if unk:
            parts.append("variables not determined by any equation: "
                         + ", ".join(self._declared_at(u) for u in unk))
        if eqs and n_eq != n_unk or (eqs and unk):
            parts.append("equations with no variable left to solve for, from: "
                         + ", ".join(self._equation_at(e) for e in eqs))
        return "; ".join(parts)


def _literal_text(val: Any) -> str:
    if isinstance(val, dict) and len(val) == 1:
        kind, v = next(iter(val.items()))
        return f"the {kind} {v!r}"
    return repr(val)


def _branch_guard(cond: Any, prior: list[Any]) -> Any:
    """The condition under which an if-branch is taken: *cond* and none of the *prior* ones."""
    guard = None if cond is None else cond
    for p in prior:
        guard = _not(p) if guard is None else ca.logic_and(guard, _not(p))
    return guard


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

# array built-ins (MLS 10.3): recognised by name when the model defines no function of that name
_ARRAY_BUILTINS = {
    "size", "ndims", "scalar", "vector", "matrix", "identity", "diagonal", "zeros", "ones", "fill",
    "linspace", "cat", "transpose", "outerproduct", "symmetric", "cross", "skew",
}


_BUILTIN_EXTERNALS = {
    "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "exp", "log", "log10",
    "sqrt", "abs", "sign", "floor", "ceil",
}
"""Functions an ``external "builtin"`` declaration may name (MLS 12.9: the built-ins of the language,
as Modelica.Math declares its elementary functions)."""


def _builtin_external(ext: Any) -> str | None:
    """The built-in an ``external "builtin"`` clause calls, or None (another language, or unknown)."""
    if not isinstance(ext, dict) or str(ext.get("language", "")).lower() != "builtin":
        return None
    name = str(ext.get("function_name") or "")
    return name if name in _BUILTIN_EXTERNALS else None


def _not(a: Any) -> Any:
    return (not a) if _num(a) else ca.logic_not(a)


def _binary(op: str, a: Value, b: Value, tr: FlatTranslator) -> Value:
    """A binary operator with its Modelica meaning (rumoca names: Add, Sub, Mul, Div, Exp, and
    AddElem ... ExpElem for the element-wise ``.+ .- .* ./ .^``)."""
    o = op.lower()
    elementwise = False
    for prefix in ("dot", "elem"):
        if o.startswith(prefix):
            o, elementwise = o[len(prefix):], True
    if o.endswith("elem"):
        o, elementwise = o[: -len("elem")], True
    if o in ("add", "plus"):
        return arr.map2(lambda x, y: x + y, a, b, "'.+'" if elementwise else "addition '+'", broadcast=elementwise)
    if o in ("sub", "minus"):
        return arr.map2(lambda x, y: x - y, a, b, "'.-'" if elementwise else "subtraction '-'",
                        broadcast=elementwise)
    if o in ("mul", "times"):
        if elementwise:
            return arr.map2(lambda x, y: x * y, a, b, "'.*'")
        return arr.matmul(a, b)
    if o == "div":
        if elementwise:
            return arr.map2(arr.scalar_div, a, b, "'./'")
        return arr.divide(a, b)
    if o in ("exp", "pow", "power"):
        if elementwise:
            return arr.map2(arr.scalar_pow, a, b, "'.^'")
        return arr.power(a, b)
    cmp = {"lt": "<", "le": "<=", "gt": ">", "ge": ">=", "eq": "==", "neq": "!=", "ne": "!="}
    if o in cmp:
        if arr.is_array(a) or arr.is_array(b):
            raise ArrayError(f"relational operator {cmp[o]} on arrays (sizes {arr.size_text(arr.shape(a))} "
                             f"and {arr.size_text(arr.shape(b))}); Modelica compares scalars only")
        x, y = a, b
        return {"<": x < y, "<=": x <= y, ">": x > y, ">=": x >= y, "==": x == y, "!=": x != y}[cmp[o]]
    if o in ("and", "or"):
        return arr.map2(_and if o == "and" else _or, a, b, f"'{o}'", broadcast=False)
    raise tr.unsupported(f"binary operator {op!r}")


def _and(a: Any, b: Any) -> Any:
    if (_num(a) and not a) or (_num(b) and not b):
        return False
    if _num(a):
        return b
    if _num(b):
        return a
    return ca.logic_and(a, b)


def _or(a: Any, b: Any) -> Any:
    if (_num(a) and a) or (_num(b) and b):
        return True
    if _num(a):
        return b
    if _num(b):
        return a
    return ca.logic_or(a, b)


_SIMPLE = {
    "sqrt": (math.sqrt, ca.sqrt), "exp": (math.exp, ca.exp), "log": (math.log, ca.log),
    "log10": (math.log10, ca.log10), "sin": (math.sin, ca.sin), "cos": (math.cos, ca.cos),
    "tan": (math.tan, ca.tan), "asin": (math.asin, ca.asin), "acos": (math.acos, ca.acos),
    "atan": (math.atan, ca.atan), "sinh": (math.sinh, ca.sinh), "cosh": (math.cosh, ca.cosh),
    "tanh": (math.tanh, ca.tanh), "abs": (abs, ca.fabs), "floor": (math.floor, ca.floor),
    "ceil": (math.ceil, ca.ceil), "sign": (lambda x: float(np.sign(x)), ca.sign),
    "integer": (lambda x: float(math.floor(x)), ca.floor),
}


def _arity(name: str, args: list[Value], *allowed: int) -> None:
    if len(args) not in allowed:
        want = " or ".join(str(n) for n in allowed)
        raise ArrayError(f"{name}() takes {want} argument(s), got {len(args)}")


def _builtin(name: str, args: list[Value], tr: FlatTranslator) -> Value:
    n = name.lower()
    if n in _SIMPLE:
        _arity(n, args, 1)
        f_num, f_sym = _SIMPLE[n]
        return arr.map1(lambda a: arr.fold_math(n, f_num, a) if _num(a) else f_sym(a), args[0])
    if n == "noevent":
        return args[0]
    if n == "smooth":
        return args[1]
    if n == "homotopy":
        return args[0]
    if n == "semilinear":
        x, a, b = args
        return ca.if_else(x >= 0, a * x, b * x) if not _num(x) else (a * x if x >= 0 else b * x)
    if n == "atan2":
        _arity(n, args, 2)
        return arr.map2(lambda y, x: math.atan2(y, x) if _num(y) and _num(x) else ca.atan2(y, x),
                        args[0], args[1], "atan2()")
    if n in ("min", "max"):
        _arity(n, args, 1, 2)
        if len(args) == 1:  # reduction over an array (or a comprehension)
            if not arr.is_array(args[0]):
                raise ArrayError(f"{n}() of one scalar: it needs an array or two scalars")
            return arr.extremum(arr.elements(args), n)
        if arr.is_array(args[0]) or arr.is_array(args[1]):
            raise ArrayError(f"{n}(a, b) of sizes {arr.size_text(arr.shape(args[0]))} and "
                             f"{arr.size_text(arr.shape(args[1]))}: it takes two scalars or one array")
        return arr.extremum(list(args), n)
    if n == "sum":
        _arity(n, args, 1)
        return arr.reduce_sum(args[0])
    if n == "product":
        _arity(n, args, 1)
        return arr.reduce_product(args[0])
    if n in ("div", "mod", "rem"):
        _arity(n, args, 2)
        return arr.map2(lambda a, b: _divmod(n, a, b, tr), args[0], args[1], f"{n}()", broadcast=False)
    if n == "size":
        _arity(n, args, 1, 2)
        return arr.sizes(args[0], args[1] if len(args) == 2 else None)
    if n == "ndims":
        _arity(n, args, 1)
        return len(arr.shape(args[0]))
    if n == "scalar":
        _arity(n, args, 1)
        return arr.to_scalar(args[0])
    if n == "vector":
        _arity(n, args, 1)
        return arr.to_vector(args[0])
    if n == "matrix":
        _arity(n, args, 1)
        return arr.to_matrix(args[0])
    if n == "identity":
        _arity(n, args, 1)
        (size,) = arr.ints(args, "identity()")
        return arr.identity(size)
    if n == "diagonal":
        _arity(n, args, 1)
        return arr.diagonal(args[0])
    if n in ("zeros", "ones"):
        return arr.fill(0.0 if n == "zeros" else 1.0, args, f"{n}()")
    if n == "fill":
        if len(args) < 2:
            raise ArrayError("fill() needs a value and at least one size")
        return arr.fill(args[0], args[1:])
    if n == "linspace":
        _arity(n, args, 3)
        return arr.linspace(*args)
    if n == "cat":
        if len(args) < 2:
            raise ArrayError("cat() needs a dimension and at least one array")
        return arr.cat(args[0], args[1:])
    if n == "transpose":
        _arity(n, args, 1)
        return arr.transpose(args[0])
    if n == "outerproduct":
        _arity(n, args, 2)
        return arr.outer(args[0], args[1])
    if n == "symmetric":
        _arity(n, args, 1)
        return arr.symmetric(args[0])
    if n == "cross":
        _arity(n, args, 2)
        return arr.cross(args[0], args[1])
    if n == "skew":
        _arity(n, args, 1)
        return arr.skew(args[0])
    raise tr.unsupported(f"built-in {n}()", rf"\b{n}\s*\(")


def _divmod(n: str, a: Value, b: Value, tr: FlatTranslator) -> Value:
    if _num(a) and _num(b):
        if float(b) == 0.0:
            raise ArrayError(f"{n}({a}, {b}): division by zero")
        if n == "div":
            return float(math.trunc(a / b))
        if n == "mod":
            return a - math.floor(a / b) * b
        return a - math.trunc(a / b) * b
    if n == "mod":
        return a - ca.floor(a / b) * b
    q = a / b
    truncated = ca.sign(q) * ca.floor(ca.fabs(q))  # integer part, towards zero
    if n == "div":
        return truncated
    return a - truncated * b


def _span_hint(body: Any) -> str | None:
    """A word the source text at an expression's span must contain (to pick the right file)."""
    if not isinstance(body, dict):
        return None
    if "function" in body:
        return str(body["function"])
    name = body.get("name")
    if isinstance(name, dict) and isinstance(name.get("name"), str):
        return name["name"].rsplit(".", 1)[-1]
    return None


_OP_TEXT = {
    "add": "+", "sub": "-", "mul": "*", "div": "/", "exp": "^", "addelem": ".+", "subelem": ".-",
    "mulelem": ".*", "divelem": "./", "expelem": ".^", "lt": "<", "le": "<=", "gt": ">", "ge": ">=",
    "eq": "==", "neq": "<>", "ne": "<>", "and": "and", "or": "or",
}


def expression_text(node: Any, depth: int = 0) -> str:
    """Modelica-like text of a flat-model expression, for error messages."""
    if depth > 12:
        return "..."
    kind, body = _kind_of(node)
    sub = lambda n: expression_text(n, depth + 1)  # noqa: E731
    try:
        if kind == "Literal":
            _k, val = _kind_of(body["value"])
            if isinstance(val, bool):
                return "true" if val else "false"
            return repr(val) if isinstance(val, str) else f"{val}"
        if kind == "VarRef":
            subs = body.get("subscripts") or []
            return body["name"]["name"] + (("[" + ", ".join(_sub_text(s, depth) for s in subs) + "]") if subs else "")
        if kind == "Binary":
            op = _OP_TEXT.get(str(body["op"]).lower(), str(body["op"]))
            return f"({sub(body['lhs'])} {op} {sub(body['rhs'])})"
        if kind == "Unary":
            op = "-" if "minus" in str(body.get("op")).lower() else ("not " if str(body.get("op")).lower() == "not" else "")
            return f"{op}{sub(body.get('rhs', body.get('arg', body.get('expr'))))}"
        if kind == "BuiltinCall":
            return f"{str(body['function'])[:1].lower()}{str(body['function'])[1:]}(" + ", ".join(
                sub(a) for a in body.get("args") or []) + ")"
        if kind == "FunctionCall":
            return f"{body['name']['name']}(" + ", ".join(sub(a) for a in body.get("args") or []) + ")"
        if kind == "Array":
            els = body.get("elements", []) if isinstance(body, dict) else body
            k = body.get("kind", "Array") if isinstance(body, dict) else "Array"
            if k == "Horizontal":
                return "[" + ", ".join(sub(e) for e in els) + "]"
            if k == "Vertical":
                return "[" + "; ".join(sub(e).strip("[]") for e in els) + "]"
            return "{" + ", ".join(sub(e) for e in els) + "}"
        if kind == "Range":
            step = f"{sub(body['step'])}:" if body.get("step") is not None else ""
            return f"{sub(body['start'])}:{step}{sub(body['end'])}"
        if kind == "ArrayComprehension":
            its = ", ".join(f"{ix['name']} in {sub(ix['range'])}" for ix in body.get("indices") or [])
            return "{" + f"{sub(body['expr'])} for {its}" + "}"
        if kind == "Index":
            return sub(body["base"]) + "[" + ", ".join(_sub_text(s, depth) for s in body.get("subscripts") or []) + "]"
        if kind == "Tuple":
            return "(" + ", ".join("" if _kind_of(e)[0] == "Empty" else sub(e) for e in body.get("elements") or []) + ")"
        if kind == "If":
            return "if ... then ... else ..."
        if kind == "Parenthesized":
            return sub(body.get("inner", body))
    except (KeyError, TypeError, AttributeError):
        pass
    return f"<{kind}>"


def _sub_text(s: Any, depth: int) -> str:
    kind, body = _kind_of(s)
    if kind == "Index":
        return str(body["value"])
    if kind == "Colon":
        return ":"
    if kind == "Expr":
        return expression_text(body["expr"], depth + 1)
    return "?"


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


def check_lost_der_equations(flat: dict[str, Any], source: ModelicaSource, model: str,
                             libraries: tuple[Path, ...] = ()) -> None:
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

    files = model_files(source, model, libraries=libraries)
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
