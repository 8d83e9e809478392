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

Events (:mod:`.events`): relations on continuous-time values outside ``noEvent``
and ``integer``/``floor``/``ceil`` of such values are held between events with
event indicators; discrete variables, when-clauses (equations and statements),
``reinit``, ``pre``/``edge``/``change``/``initial()``/``terminal()``/``sample()``
become the FMU's event iteration. ``min``/``max``/``abs`` are evaluated as they
stand (no events); relations inside functions and ``noEvent``/``smooth`` too.
Algorithm sections and initial algorithm sections are executed symbolically
(:meth:`FlatTranslator.algorithm_residuals`). A structurally singular system is
handed to index reduction (:mod:`.index`). The MSL's table functions are built
as expressions (:mod:`.tables`).

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
are the initial equations (and ``v = start`` for a variable that is not a state
with ``fixed = true``), in which ``der(x)`` and the algebraic variables are
replaced by their causalised expressions, plus ``x = start`` for states with
``fixed = true``. If there are fewer equations than unknowns, states that no
initial equation mentions keep their start values. The system is solved block
by block (explicitly where a block is linear in its unknown, else by a Newton
rootfinder compiled into the FMU, from the current values as guesses) with the
parameters as the user set them. Models without initial equations are exported
exactly as before.

Anything else (``delay``, ``terminate``, clocks, external functions other than
``"builtin"`` ones and the MSL's tables, ...) raises
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
from . import tables
from .arrays import ArrayError
from .causalize import StructuralError, blt
from .events import Condition, EventSystem, Sample, WhenCondition
from .index import IndexError_, max_matching, reduce_index
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
    guesses: list[ca.MX] = field(default_factory=list)
    solution: list[ca.MX] = field(default_factory=list)
    """The unknowns solved block by block (a scalar equation linear in its unknown explicitly, a loop by
    Newton from ``guesses``, the unknowns' values when the FMU leaves initialisation mode), as
    expressions in ``guesses`` and ``knowns``; empty: one Newton solve of all ``residual``."""


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
    events: EventSystem | None = None
    discrete: list[ScalarVar] = field(default_factory=list)


def _kind_of(node: Any) -> tuple[str, Any]:
    if isinstance(node, dict) and len(node) == 1:
        key = next(iter(node))
        return key, node[key]
    return type(node).__name__, node


_UNSUPPORTED_BUILTINS = {
    "reinit": r"\breinit\s*\(",
    "delay": r"\bdelay\s*\(",
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


_EVENT_BUILTINS = {"pre", "edge", "change", "initial", "terminal", "sample"}
_RETURNED = "\0returned"  # in a function's environment: where a return statement was taken
HYSTERESIS = 1e-10
"""Relative shift of event indicators past the switching point (see FlatTranslator.relation)."""


def _num(x: Value) -> bool:
    return isinstance(x, (int, float, bool, np.integer, np.floating, np.bool_))


def _plain_ge(a: Value, b: Value) -> Value:
    """``a >= b`` evaluated as it stands (no event)."""
    if _num(a) and _num(b):
        return a >= b
    return (ca.MX(a) if _num(a) else a) >= b


def _if(cond: Value, a: Value, b: Value) -> Value:
    """``if cond then a else b`` for scalars (a constant condition picks a branch)."""
    if _num(cond):
        return a if bool(cond) else b
    if a is b:
        return a
    return ca.if_else(cond, a, b)


def _when_targets(flat: dict[str, Any]) -> set[str]:
    """Variables (their flat names, subscripts of the last part removed) that when-clauses and
    when-statements assign: they are discrete (MLS 4.5: a Real assigned in a when-clause)."""
    found: set[str] = set()
    for chain in flat.get("when_chains") or []:
        for br in [chain.get("first") or {}, *(chain.get("else_when") or [])]:
            for eq in br.get("equations") or []:
                kind, body = _kind_of(eq)
                if kind == "Assign" and isinstance(body, dict):
                    found.add(re.sub(r"\[[^\]]*\]$", "", str(body.get("target"))))

    def statements(stmts: list[Any], inside: bool) -> None:
        for st in stmts or []:
            kind, body = _kind_of(st)
            if not isinstance(body, dict):
                continue
            if kind == "Assignment" and inside:
                parts = (body.get("comp") or {}).get("parts") or []
                names = []
                for k, part in enumerate(parts):
                    subs = part.get("subs") or [] if k < len(parts) - 1 else []
                    idx = [str(_kind_of(sb)[1].get("value")) for sb in subs
                           if _kind_of(sb)[0] == "Index" and isinstance(_kind_of(sb)[1], dict)]
                    names.append(str(part.get("ident")) + (f"[{','.join(idx)}]" if idx else ""))
                found.add(".".join(names))
            elif kind == "When":
                for blk in body.get("blocks") or []:
                    statements(blk.get("stmts") or [], True)
            for key in ("cond_blocks", "branches", "blocks"):
                for blk in body.get(key) or []:
                    if isinstance(blk, dict) and kind != "When":
                        statements(blk.get("stmts") or blk.get("body") or [], inside)
            for key in ("else_block", "else_branch", "equations", "stmts", "body"):
                if isinstance(body.get(key), list):
                    statements(body[key], inside)

    for section in (flat.get("algorithms") or []) + (flat.get("initial_algorithms") or []):
        statements(section.get("statements") or [], False)
    return found


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
        # events (.events): relations and roundings frozen between events, when conditions, pre()
        self.events = EventSystem(initial=ca.MX.sym("_tbx_initial"))
        self.quiet = ca.MX.sym("_tbx_quiet")  # 1 when sample() instants are over (see fmi_export)
        self._freeze = True
        self._frozen: dict[str, ca.MX] = {}
        self._pre: dict[str, ca.MX] = {}
        self._when_targets: set[str] = set()
        self._uses_initial = False
        self._discrete_defs: list[tuple[ca.MX, str]] = []  # when-equations, discrete outputs of algorithms

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
        known = None
        if span is not None:
            known = self._sources.get(span.get("source")) if self._sources else None
            # without the span's file known, only a file whose text there matches the construct counts
            files = (known,) if known is not None else (self._files if pattern or len(self._files) == 1 else ())
            loc = span_location(span, files, pattern)
            if loc is not None:
                return [loc]
        if pattern:
            locs = locate(self.source, self.model, pattern, libraries=self.libraries)
            if locs:
                return locs
        if span is not None and pattern and (known is not None or len(self._files) == 1):
            loc = span_location(span, (known,) if known is not None else self._files, None)
            if loc is not None:
                return [loc]
        return []

    def unsupported(self, construct: str, pattern: str | None = None, detail: str = "", *,
                    span: dict[str, Any] | None = None) -> UnsupportedConstructError:
        locs = self.location(pattern, span)
        where = (" at " + ", ".join(str(loc) for loc in locs)) if locs else ""
        if not locs:  # at least the model's declaration
            decl = locate(self.source, self.model, rf"\b(?:model|block|class)\s+{re.escape(self.model.rsplit('.', 1)[-1])}\b",
                          limit=1, own=True, libraries=self.libraries)
            where = f" ({self.model} is declared at {decl[0]}; the construct's own line is not known)" if decl else ""
        msg = (
            f"unsupported Modelica construct in {self.model}: {construct}{where}"
            f"{': ' + detail if detail else ''}. The embedded backend cannot compile it; "
            "use --backend openmodelica where omc is installed, or rewrite the model"
        )
        return UnsupportedConstructError(msg)

    # --------------------------------------------------------------- checks
    def check_constructs(self) -> None:
        flat = self.flat


    # ------------------------------------------------------------ variables
    def _type_of(self, v: dict[str, Any]) -> int:
        if v.get("type_id") in (self.flat.get("enumeration_types") or []):
            return INTEGER  # an enumeration value is its ordinal (MLS 4.9.5)
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
        self._when_targets = _when_targets(self.flat)
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
            elif caus_kind == "Input" and (name in top_inputs or top):
                kind = "input"
            elif var_kind == "Discrete" or vtype != REAL or name in self._when_targets:
                kind = "discrete"  # held between events (.events)
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
                if kind in ("parameter", "input", "continuous", "discrete"):
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
        if str(op).lower() in ("and", "or") and _num(lhs) and bool(lhs) == (str(op).lower() == "or"):
            return bool(lhs)  # false and ..., true or ...: the other operand is not evaluated
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
        if lname in _EVENT_BUILTINS:
            return self._event_builtin(lname, args_nodes, env)
        if lname in ("noevent", "smooth"):  # relations inside generate no events
            saved, self._freeze = self._freeze, False
            try:
                args = [self.expr(a, env) for a in args_nodes]
            finally:
                self._freeze = saved
            return _builtin(lname, args, self)
        args = [self.expr(a, env) for a in args_nodes]
        return _builtin(lname, args, self)

    # --------------------------------------------------------------- events
    def _is_continuous(self, value: Value) -> bool:
        """Whether *value* depends on a continuous-time variable (or time): a relation on it switches
        between events and must be frozen (.events)."""
        if _num(value) or not isinstance(value, ca.MX):
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
        if (_num(a) and _num(b)) or (isinstance(a, str) and isinstance(b, str)):
            return {"<": a < b, "<=": a <= b, ">": a > b, ">=": a >= b, "==": a == b, "!=": a != b}[op]
        x, y = (ca.MX(a) if _num(a) else a), (ca.MX(b) if _num(b) else b)
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

    def _pre_value(self, node: Any) -> Value:
        """``pre(v)``: the value of *v* before the current event-iteration step; for a continuous-time
        variable its value at the event (its left limit)."""
        value = self.expr(node, None)

        def one(x: Value) -> Value:
            if _num(x) or not isinstance(x, ca.MX):
                return x
            syms = [s for s in ca.symvar(x) if (sv := self.scalars.get(s.name())) is not None and sv.kind == "discrete"]
            if not syms:
                return x
            return ca.substitute([x], syms, [self.pre_sym(self.scalars[s.name()]) for s in syms])[0]

        return arr.map1(one, value)

    def _event_builtin(self, name: str, nodes: list[Any], env: Any) -> Value:
        if name == "pre":
            return self._pre_value(nodes[0])
        if name == "edge":
            b, p = self.expr(nodes[0], env), self._pre_value(nodes[0])
            return arr.map2(lambda x, y: _and(x, _not(y)), b, p, "edge()", broadcast=False)
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
            self.events.samples.append(Sample(sym, ca.MX(start) if _num(start) else start,
                                              ca.MX(interval) if _num(interval) else interval))
            return sym
        raise self.unsupported(f"built-in {name}()")  # pragma: no cover - _EVENT_BUILTINS lists the above

    def when_fire(self, node: Any, env: Any) -> Value:
        """The firing of a when condition (``c and not pre(c)`` for each element of it); each element
        becomes a held when condition of the event iteration."""
        cond = self.expr(node, env)
        fire: Value = False
        for el in (list(cond.ravel()) if arr.is_array(cond) else [cond]):
            if _num(el):
                continue  # a constant condition never becomes true
            k = len(self.events.whens) + 1
            sym, pre = ca.MX.sym(f"_tbx_w{k}"), ca.MX.sym(f"pre(_tbx_w{k})")
            initial = bool(ca.depends_on(el, self.events.initial))
            self.events.whens.append(WhenCondition(sym, pre, el, initial))
            edge = ca.logic_and(sym, ca.logic_not(pre))
            if not initial:  # a when-clause fires at initialisation only by initial()
                edge = ca.logic_and(edge, ca.logic_not(self.events.initial))
            fire = _or(fire, edge)
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
                kind, body = _kind_of(eq)
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
                expr = _if(fires[bi], by_branch.get(bi, self.pre_sym(sv)), expr)
            self._discrete_defs.append((sv.sym - expr, f"when-clause assignment to {name}"))
        for name, by_branch in reinits.items():
            sv = self.scalars[name]
            if sv.kind != "continuous":
                raise self.unsupported(f"reinit({name}) of a variable that is not a state", r"\breinit\s*\(")
            expr = sv.sym
            for bi in reversed(range(len(branches))):
                expr = _if(fires[bi], by_branch.get(bi, sv.sym), expr)
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
        if fname in _BUILTIN_NAMES or (fname.lower() in _ARRAY_BUILTINS and fname not in self.functions):
            return _builtin(fname.lower(), args, self)
        fn = self.functions.get(fname)
        if fn is None:
            raise CompileError(f"call of unknown function {fname!r} in {self.model}")
        outs = self.inline(fname, fn, args)
        return outs[0]

    # --------------------------------------------------------------- tables
    def _table_call(self, fname: str, nodes: list[Any], env: Any) -> Value:
        """A call of the MSL's table functions on a table object (.tables)."""
        kind, ref = _kind_of(nodes[0]) if nodes else ("", None)
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
                        return self.relation(">=", a, b) if events else _plain_ge(a, b)
                else:
                    ge = _plain_ge
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
            self._record_assert(_and(lo, hi), f"extrapolation error: the abscissa is outside the table {tab.name} "
                                f"[{tab.grid[0]:g}, {tab.grid[-1]:g}] (NoExtrapolation)", "error", tab.name)
        return check

    def _table(self, name: str) -> tables.Table:
        """The table object bound to the parameter *name* (its constructor call's arguments evaluated)."""
        cache = self.__dict__.setdefault("_tables", {})
        if name in cache:
            return cache[name]
        var = (self.flat.get("variables") or {}).get(name) or {}
        kind, call = _kind_of(var.get("binding"))
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
        if ext:
            raise self.unsupported(f"external function {fname!r}", r"\bexternal\b")
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
                elif loc.get("dims"):  # an array declared with its sizes: its elements can be assigned
                    dims = self._local_dims(loc, env, fname)
                    if dims is not None:
                        env[loc["name"]] = arr.fill(0.0, list(dims))
            saved, self._freeze = self._freeze, False  # relations in functions generate no events
            env[_RETURNED] = False
            try:
                self._statements(fn.get("body") or [], env, fname)
            finally:
                self._freeze = saved
            outs = []
            for out in fn.get("outputs") or []:
                if out["name"] not in env:
                    raise CompileError(f"function {fname!r} does not assign its output {out['name']!r}")
                outs.append(env[out["name"]])
            return outs
        finally:
            self._inline_depth -= 1

    def _local_dims(self, loc: dict[str, Any], env: dict[str, Value], fname: str) -> tuple[int, ...] | None:
        """The sizes of a function's local or output array (None when one is flexible, ``:``)."""
        out = []
        for d in loc.get("dims") or []:
            if isinstance(d, int):
                out.append(d)
                continue
            if _kind_of(d)[0] in ("Colon", "Empty") or d is None:
                return None
            val = self.expr(d, env)
            if not _num(val):
                return None
            out.append(int(val))
        return tuple(out)

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
            if _RETURNED in env and _num(env[_RETURNED]) and bool(env[_RETURNED]):
                return  # after a return taken on every path, nothing more happens
            kind, body = _kind_of(st)
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
            elif kind == "Assert":
                self.add_assert(body, env, fname if _is_algorithm(fname) else f"function {fname}")
            else:
                pattern = {"While": r"\bwhile\b", "Return": r"\breturn\b", "Break": r"\bbreak\b"}.get(kind)
                raise self.unsupported(f"{kind.lower()} statement {_in(fname)}", pattern)

    def _assign(self, parts: list[dict[str, Any]], value: Value, env: dict[str, Value], fname: str) -> None:
        """``target := value`` in a function or algorithm (a whole variable, array elements or slices);
        after a possible return, only where the function has not returned."""
        if len(parts) != 1 and not _is_algorithm(fname):
            raise self.unsupported(f"record field assignment {_in(fname)}")
        ident = self._flat_target(parts, env)
        subs = parts[-1].get("subs") or []
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
        if not (_num(returned) and not bool(returned)) and old is not None:
            value = arr.map2(lambda a, b: _if(returned, a, b), old, value, f"assignment to {ident!r}",
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
        """An if-statement (or, given *conds*, the branches of a when-statement with their firings)."""
        blocks = body.get("cond_blocks") or body.get("branches") or []
        else_block = body.get("else_block") or body.get("else_branch") or []
        conds_and_envs = []
        prior: list[Any] = []  # symbolic conditions of the branches before (for asserts in branches)
        for k, blk in enumerate(blocks):
            if isinstance(blk, dict):
                cond_node, stmts = blk.get("cond"), blk.get("stmts", blk.get("body", []))
            else:
                cond_node, stmts = blk
            cond = conds[k] if conds is not None else self.expr(cond_node, env)
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
        saved, self._freeze = self._freeze, False  # an assert is checked as its condition stands (no events)
        try:
            cond = self.expr(body["condition"], env)
        finally:
            self._freeze = saved
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
            raise self.unsupported(f"for-loop with {len(indices)} indices {_in(fname)}")
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
            if sv.kind in ("continuous", "discrete") and sv.binding_node is not None:
                residuals.append((sv.sym - self._element(sv, sv.binding_node), f"binding of {sv.name}"))
        for section in self.flat.get("algorithms") or []:
            residuals.extend(self.algorithm_residuals(section, initial=False))
        for chain in self.flat.get("when_chains") or []:
            residuals.extend(self.when_chain(chain))

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
        for section in self.flat.get("initial_algorithms") or []:
            init_residuals.extend(self.algorithm_residuals(section, initial=True))
        extra = [n for n in self.der_placeholders if n not in state_names]
        if extra:
            raise self.unsupported(
                f"der({extra[0]}) in an initial equation, where {extra[0]} is not a state "
                "(no equation of the model differentiates it)", r"\binitial\s+equation\b")
        algebraics = [sv for sv in self.scalars.values() if sv.kind == "continuous" and sv.name not in state_names]
        for sv in algebraics:  # fixed = true on a variable that is not a state: an initial equation v = start
            if sv.fixed is True and sv.start_node is not None:
                init_residuals.append((sv.sym - self._element(sv, sv.start_node), f"start value of {sv.name} "
                                       "(fixed = true)"))
        unknowns: list[ca.MX] = [self.der_placeholders[s.name] for s in states]
        unknowns += [sv.sym for sv in algebraics] + [sv.sym for sv in calculated]
        unknown_names = [u.name() for u in unknowns]
        position = {n: i for i, n in enumerate(unknown_names)}
        # events: the equations of discrete variables are solved at events only (.events); between
        # events the continuous equations see them (and pre(v) = v) held
        discrete = [sv for sv in self.scalars.values() if sv.kind == "discrete"]
        # (calculated parameters are unknowns of the continuous equations but known at events)
        time_varying = set(unknown_names) - {sv.name for sv in calculated}
        residuals, discrete_residuals = self._split_discrete(residuals, time_varying, discrete)
        discrete_residuals += self._discrete_defs
        init_residuals, discrete_initial = self._split_discrete(init_residuals, time_varying, discrete,
                                                                initial=True)
        incidence = []
        for r, _origin in residuals:
            incidence.append(sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position}))
        optional_init: list[tuple[ca.MX, str]] = []
        try:
            blocks = blt(incidence, len(unknowns))
        except StructuralError as exc:
            # a DAE of higher index: differentiate the constraints and choose the states (.index)
            reduced = self._reduce_index(residuals, states, algebraics, calculated, calc_eqs)
            if reduced is None:
                raise CompileError(self._structural_message(exc, residuals, unknown_names)) from None
            residuals, states, optional_init = reduced
            state_names = {s.name for s in states}
            algebraics = [sv for sv in self.scalars.values()
                          if sv.kind == "continuous" and sv.name not in state_names]
            unknowns = [self.der_placeholders[s.name] for s in states]
            unknowns += [sv.sym for sv in algebraics] + [sv.sym for sv in calculated]
            unknown_names = [u.name() for u in unknowns]
            position = {n: i for i, n in enumerate(unknown_names)}
            incidence = [sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position})
                         for r, _origin in residuals]
            try:
                blocks = blt(incidence, len(unknowns))
            except StructuralError as exc2:
                raise CompileError(self._structural_message(exc2, residuals, unknown_names)) from None

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
            tears, solved, residual = self._tear(res, unk, guess)
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
        events = self._event_system(discrete, discrete_residuals, discrete_initial)
        initial = None
        if init_residuals or computed or optional_init:
            initial = self._initial_system(init_residuals, states, computed, assignments, optional_init)
            if not initial.unknowns:
                initial = None
        asserts = self._unique_asserts()
        exprs = [e for _, e in assignments] + [a.condition for a in asserts]
        if initial is not None:
            exprs += initial.residual
        if events is not None:
            exprs += [e for _, e in events.updates] + [e for _, e in events.reinits] + events.indicators
            exprs += [x for smp in events.samples for x in (smp.start, smp.interval)]
        used = {s.name() for s in ca.symvar(ca.vertcat(*exprs))} if exprs else set()
        used |= {sv.name for sv in computed}
        unused = [sv.name for sv in params if sv.name not in used]
        params = [sv for sv in params if sv.name in used]
        return ExplicitModel(
            asserts=asserts, initial=initial, events=events, discrete=discrete,
            name=self.model, time=self.time, parameters=params, calculated=calculated, unused_parameters=unused,
            inputs=[sv for sv in self.scalars.values() if sv.kind == "input"],
            states=states, algebraics=algebraics, derivative=dict(self.der_placeholders),
            assignments=assignments, n_loops=len(loop_sizes), loop_sizes=loop_sizes, torn_sizes=torn_sizes,
        )

    def _split_discrete(self, residuals: list[tuple[ca.MX, str]], continuous: set[str], discrete: list[ScalarVar],
                        initial: bool = False) -> tuple[list[tuple[ca.MX, str]], list[tuple[ca.MX, str]]]:
        """(continuous equations, equations of discrete variables). An equation belongs to a discrete
        variable when no continuous unknown is in it and a discrete variable is (in an initial equation,
        also pre(v), which is v there). In the continuous equations pre(v) is v (between events)."""
        names = {sv.name for sv in discrete}
        pres = [(self._pre[n], self.scalars[n].sym) for n in self._pre]
        cont, disc = [], []
        for r, origin in residuals:
            held = ca.substitute([r], [a for a, _ in pres], [b for _, b in pres])[0] if pres else r
            used = {sym.name() for sym in ca.symvar(held)}
            if used & names and not used & continuous and not (initial and used & set(self.der_placeholders)):
                # at an event pre(v) is the value before the step; at initialisation it is v
                disc.append((held if initial else r, origin))
            else:
                cont.append((held, origin))
        return cont, disc

    def _event_system(self, discrete: list[ScalarVar], residuals: list[tuple[ca.MX, str]],
                      initial: list[tuple[ca.MX, str]]) -> EventSystem | None:
        """The event iteration's assignments (.events): conditions and samples first, then the when
        conditions and the discrete variables in dependency order; an initial equation or initial
        algorithm of a discrete variable gives its value at initialisation."""
        ev = self.events
        if not (discrete or ev.conditions or ev.samples or ev.whens or ev.reinits or self._uses_initial):
            return None
        unknowns = [sv.sym for sv in discrete] + [w.sym for w in ev.whens]
        eqs = list(residuals) + [(w.sym - w.value, f"when condition {w.sym.name()}") for w in ev.whens]
        assigned = self._discrete_order(eqs, unknowns, "equations of discrete variables")
        at_start = dict(self._discrete_order(initial, [sv.sym for sv in discrete], "initial equations of discrete "
                                             "variables", partial=True)) if initial else {}
        t = self.time
        updates: list[tuple[ca.MX, ca.MX]] = [(c.sym, c.value) for c in ev.conditions]
        for smp in ev.samples:
            eps = 1e-9 * ca.fmax(1, ca.fabs(t))
            k = ca.floor((t - smp.start) / smp.interval + 0.5)
            at = ca.logic_and(t >= smp.start - eps, ca.fabs(t - smp.start - k * smp.interval) <= eps)
            quiet = ca.logic_or(self.quiet, ev.initial)  # sample() is never true at initialisation
            updates.append((smp.sym, ca.logic_and(at, ca.logic_not(quiet))))
        for sym, expr in assigned:
            if sym.name() in {k.name() for k in at_start}:
                expr = ca.if_else(ev.initial, at_start[next(k for k in at_start if k.name() == sym.name())], expr)
            updates.append((sym, expr))
        ev.updates = updates
        pres = [(self._pre[n], self.scalars[n].sym) for n in self._pre]
        if pres:  # between events (where indicators are evaluated) pre(v) is v
            for cond in ev.conditions:
                cond.indicators = ca.substitute(cond.indicators, [a for a, _ in pres], [b for _, b in pres])
        ev.discrete = [(sv.name, sv.sym, self._start_of(sv)) for sv in discrete]
        ev.pre = dict(self._pre)
        return ev

    def _discrete_order(self, eqs: list[tuple[ca.MX, str]], unknowns: list[ca.MX], what: str,
                        partial: bool = False) -> list[tuple[ca.MX, ca.MX]]:
        """Solve equations of discrete variables one at a time, each for its variable, in dependency
        order (a loop of discrete variables is refused, naming them)."""
        names = [u.name() for u in unknowns]
        position = {n: i for i, n in enumerate(names)}
        incidence = [sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position}) for r, _ in eqs]
        if partial:  # initial equations of some discrete variables: match each to the one it has
            out = []
            for (r, origin), inc in zip(eqs, incidence):
                if len(inc) != 1:
                    raise self.unsupported(f"initial equation of several discrete variables ({origin})")
                sol = _solve_scalar_linear(r, unknowns[inc[0]])
                if sol is None:
                    raise self.unsupported(f"initial equation of discrete variable {names[inc[0]]} that is not "
                                           f"explicit in it ({origin})")
                out.append((unknowns[inc[0]], sol))
            return out
        try:
            blocks = blt(incidence, len(unknowns))
        except StructuralError as exc:
            und = [names[j] for j in exc.unknowns][:8]
            eq = sorted({eqs[i][1] for i in exc.equations})[:8]
            raise CompileError(
                f"the {what} of {self.model} do not determine them: {len(eqs)} equations for {len(unknowns)} "
                f"variables" + (f"; not determined: {', '.join(und)}" if und else "")
                + (f"; equations with no variable left: {', '.join(eq)}" if eq else "")) from None
        out: list[tuple[ca.MX, ca.MX]] = []
        for block in blocks:
            if len(block.unknowns) != 1:
                loop = ", ".join(names[j] for j in block.unknowns[:8])
                raise self.unsupported(f"algebraic loop among discrete variables ({loop})")
            r, origin = eqs[block.equations[0]]
            u = unknowns[block.unknowns[0]]
            sol = _solve_scalar_linear(r, u)
            if sol is None:
                raise self.unsupported(f"equation of discrete variable {u.name()} that is not explicit in it "
                                       f"({origin})")
            out.append((u, sol))
        return out

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

    def _start_of(self, sv: ScalarVar) -> float:
        """The start value of a variable (0 when it has none), with parameters at their start values."""
        if sv.kind == "parameter" and sv.value is not None and sv.fixed is not False:
            return float(sv.value)
        node = sv.start_node
        if node is None:
            return 0.0
        try:
            return self.numeric(self._element(sv, node), f"start value of {sv.name!r}")
        except CompileError:
            return 0.0

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

    def _needed_optional(self, residuals: list[tuple[ca.MX, str]], optional: list[tuple[ca.MX, str]],
                         states: list[ScalarVar], computed: list[ScalarVar],
                         assignments: list[tuple[ca.MX, ca.MX]]) -> list[tuple[ca.MX, str]]:
        """Those of *optional* initial equations that determine an unknown of the initialisation problem
        (free states, fixed = false parameters) that the others leave undetermined (by structural rank)."""
        free = [s for s in states if s.fixed is not True] + list(computed)
        position = {s.sym.name(): i for i, s in enumerate(free)}
        exprs = [r for r, _ in residuals] + [r for r, _ in optional]
        for var, val in reversed(assignments):
            if any(ca.depends_on(e, var) for e in exprs):
                exprs = ca.substitute(exprs, [var], [val])
        incid = [sorted({position[v.name()] for v in ca.symvar(e) if v.name() in position}) for e in exprs]
        kept = incid[:len(residuals)]
        rank = max_matching(kept)
        out = []
        for k, (r, origin) in enumerate(optional):
            trial = kept + [incid[len(residuals) + k]]
            if rank < len(free) and max_matching(trial) > rank:
                kept, rank = trial, rank + 1
                out.append((r, origin))
        return out

    def _reduce_index(self, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar], algebraics: list[ScalarVar],
                      calculated: list[ScalarVar], calc_eqs: list[tuple[ca.MX, str]]
                      ) -> tuple[list[tuple[ca.MX, str]], list[ScalarVar], list[tuple[ca.MX, str]]] | None:
        """Index reduction (.index) of the continuous equations; None when it cannot help. Returns the
        equations (the parameters' bindings, then the original and differentiated ones), the states
        chosen, and the initial equations v = start of former states with fixed = true, which hold
        where they are needed (a position prescribed elsewhere makes its own start redundant)."""
        calc_names = {sv.name for sv in calculated}
        eqs = [(r, o) for r, o in residuals if not any(o == c for _, c in calc_eqs)]
        preference = {}
        for name, v in (self.flat.get("variables") or {}).items():
            select = v.get("state_select") if isinstance(v, dict) else None
            if select:
                for sv in self.vars.get(name, []):
                    preference[sv.name] = str(select)
        try:
            red = reduce_index(eqs, {s.name: s.sym for s in states}, {s.name: self.der_placeholders[s.name]
                                                                      for s in states},
                               {a.name: a.sym for a in algebraics if a.name not in calc_names}, self.time,
                               {sv.name for sv in self.scalars.values() if sv.kind == "input"}, preference)
        except IndexError_ as exc:
            log.info("%s: index reduction not possible: %s", self.model, exc)
            return None
        chosen = set(red.states)
        for name, sym in red.created:  # derivatives that are algebraic unknowns (dummy derivatives)
            if name in self.scalars or any(sym is d for d in red.derivative.values()):
                continue
            self.scalars[name] = ScalarVar(name=name, kind="continuous", type=REAL, top_level=False, output=False,
                                           start_node=None, binding_node=None, index=(), attrs={},
                                           description="derivative (index reduction)", sym=sym)
        for s in states:  # a former state's derivative symbol is now an algebraic unknown
            if s.name not in chosen and s.name in self.der_placeholders:
                d = self.der_placeholders[s.name]
                self.scalars.setdefault(d.name(), ScalarVar(
                    name=d.name(), kind="continuous", type=REAL, top_level=False, output=False, start_node=None,
                    binding_node=None, index=(), attrs={}, description=f"derivative of {s.name} (dummy)", sym=d))
        self.der_placeholders = dict(red.derivative)
        new_states = [self.scalars[n] for n in red.states]
        optional = [(s.sym - self._element(s, s.start_node), f"start value of {s.name} (fixed = true)")
                    for s in states if s.name not in chosen and s.fixed is True and s.start_node is not None]
        log.info("%s: index reduction differentiated %d equations; states %s", self.model,
                 len(red.differentiated), ", ".join(red.states))
        return list(calc_eqs) + red.residuals, new_states, optional

    def _initial_system(self, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar],
                        computed: list[ScalarVar], assignments: list[tuple[ca.MX, ca.MX]],
                        optional: list[tuple[ca.MX, str]] | None = None) -> InitialSystem:
        """Build the initialisation problem (see the module docstring). *optional* initial equations
        are added where they determine an unknown the others leave free."""
        if optional:
            residuals = list(residuals) + self._needed_optional(residuals, optional, states, computed, assignments)
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
            blocks = blt(incidence, len(unknowns))
        except StructuralError as exc:
            eqs = sorted({residuals[i][1] for i in exc.equations})[:8]
            unk = [unknown_names[j] for j in exc.unknowns][:8]
            raise CompileError(
                f"the initialisation problem of {self.model} is structurally singular"
                + (f"; not determined by the initial equations: {', '.join(unk)}" if unk else "")
                + (f"; equations with no unknown left, from: {', '.join(eqs)}" if eqs else "")
            ) from None
        # solve block by block: an explicit assignment where a scalar block is linear in its unknown
        # (so e.g. a mass is found from a level before a temperature divides by it), Newton for loops
        guesses = [ca.MX.sym(f"guess({u.name()})") for u in unknowns]
        done_syms: list[ca.MX] = []
        done_vals: list[ca.MX] = []
        solution: dict[int, ca.MX] = {}
        for k, block in enumerate(blocks):
            res = [exprs[i] for i in block.equations]
            if done_syms:
                res = ca.substitute(res, done_syms, done_vals)
            unk = [unknowns[j] for j in block.unknowns]
            sols = None
            if len(unk) == 1:
                sol = _solve_scalar_linear(res[0], unk[0])
                sols = [sol] if sol is not None else None
            if sols is None:
                sols = self._rootfinder(f"init{k}", res, unk, [guesses[j] for j in block.unknowns])
            for j, sol in zip(block.unknowns, sols):
                solution[j] = sol
                done_syms.append(unknowns[j])
                done_vals.append(sol)
        return InitialSystem(
            unknowns=unknowns, knowns=[knowns[n] for n in sorted(knowns)], residual=list(exprs),
            free_states=[s.name for s in free], computed_parameters=[s.name for s in computed],
            origins=[o for _, o in residuals], guesses=guesses, solution=[solution[j] for j in range(len(unknowns))],
        )

    def _tear(self, res: list[ca.MX], unk: list[ca.MX], guess: dict[str, float] | None = None
              ) -> tuple[list[ca.MX], list[tuple[ca.MX, ca.MX]], list[ca.MX]]:
        """Greedy tearing of an algebraic loop.

        Repeatedly solve an equation that has one unknown left and is linear in
        it with a coefficient that depends on parameters only (never zero at run
        time by surprise); when none is left, make a tearing variable of an
        unknown with a start value (Newton's first guess; one without may be a
        divisor, e.g. a resistance with no start) that appears in the most
        remaining equations, else of the unknown that appears in the most. Returns the tearing
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
            # a variable with a start value (a guess for Newton) before one without, then the most used
            informed = {v: bool(guess) and abs((guess or {}).get(names[v], 0.0)) > 0 for v in unknown}
            tear = max(unknown, key=lambda v: (informed[v], counts[v], -v))
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

    def _rootfinder(self, k: int | str, res: list[ca.MX], unk: list[ca.MX], guess: list[Any]) -> list[ca.MX]:
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
        start = ca.vertcat(*guess) if guess and isinstance(guess[0], ca.MX) else ca.DM(guess)
        sol = rf(start, ca.vertcat(*other_syms) if other_syms else ca.DM.zeros(0, 1))
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


def _is_algorithm(context: str) -> bool:
    """Whether a statement context names an algorithm section of the model (not a function)."""
    return context.startswith(("algorithm ", "initial algorithm "))


def _in(context: str) -> str:
    """``in function 'f'`` or ``in the initial algorithm of pipe`` for messages."""
    return f"in the {context}" if _is_algorithm(context) else f"in function {context!r}"


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
        return tr.relation(cmp[o], a, b)
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
    if n in ("floor", "ceil", "integer"):
        _arity(n, args, 1)
        f_num = _SIMPLE[n][0]
        return arr.map1(lambda a: arr.fold_math(n, f_num, a) if _num(a) else tr.rounding(n, a), args[0])
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
