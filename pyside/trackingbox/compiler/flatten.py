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
import re
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ..errors import CompileError, UnsupportedConstructError
from . import arrays as arr
from . import records
from .causalize import StructuralError, blt
from .record_arrays import RecordArrays, element_paths
from .events import EventSystem
from .modifiers import modifier_check
from .semantics import check_flat
from .structural_params import evaluated_from_parameters, initial_definition
from .library import locate, model_files
from .source import Location, ModelicaSource, span_location, span_sources
from .flat_builtins import is_number, solve_scalar_linear
from .flat_expressions import ExpressionTranslation
from .flat_model import BOOLEAN, INTEGER, REAL, Assertion, ExplicitModel, ScalarVar, Value, kind_of
from .flat_statements import StatementTranslation
from .flat_systems import SystemAssembly
from .flat_text import check_lost_der_equations, expression_text, origin_text
from .initial_derivatives import with_initial_derivatives

log = logging.getLogger(__name__)


def _when_targets(flat: dict[str, Any]) -> set[str]:
    """Variables (their flat names, subscripts of the last part removed) that when-clauses and
    when-statements assign: they are discrete (MLS 4.5: a Real assigned in a when-clause)."""
    found: set[str] = set()
    for chain in flat.get("when_chains") or []:
        for br in [chain.get("first") or {}, *(chain.get("else_when") or [])]:
            for eq in br.get("equations") or []:
                kind, body = kind_of(eq)
                if kind == "Assign" and isinstance(body, dict):
                    found.add(re.sub(r"\[[^\]]*\]$", "", str(body.get("target"))))

    def statements(stmts: list[Any], inside: bool) -> None:
        for st in stmts or []:
            kind, body = kind_of(st)
            if not isinstance(body, dict):
                continue
            if kind in ("Assignment", "FunctionCall") and inside:
                # a := e, or (a, b) := f(...) (the outputs' targets)
                targets = ([body.get("comp") or {}] if kind == "Assignment"
                           else [t for t in body.get("outputs") or [] if isinstance(t, dict)])
                for target in targets:
                    parts = target.get("parts") or []
                    names = []
                    for k, part in enumerate(parts):
                        subs = part.get("subs") or [] if k < len(parts) - 1 else []
                        idx = [str(kind_of(sb)[1].get("value")) for sb in subs
                               if kind_of(sb)[0] == "Index" and isinstance(kind_of(sb)[1], dict)]
                        names.append(str(part.get("ident")) + (f"[{','.join(idx)}]" if idx else ""))
                    if names:
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


class FlatTranslator(ExpressionTranslation, StatementTranslation, SystemAssembly, RecordArrays):
    """Translate one rumoca flat model into an :class:`ExplicitModel`.

    The translation is one object in five modules: variables, values and the whole translation
    here; expressions in :mod:`.flat_expressions`, functions and algorithms in
    :mod:`.flat_statements`, the assembled systems in :mod:`.flat_systems`, arrays of records
    and components used whole, sliced or through a field in :mod:`.record_arrays`.
    """

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
        self._evaluated: dict[str, float | None] = {}
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
        self._pre_continuous: dict[str, ca.MX] = {}  # pre(y) of a continuous-time y: its left limit
        self._when_targets: set[str] = set()
        self._uses_initial = False
        self._discrete_defs: list[tuple[ca.MX, str]] = []  # when-equations, discrete outputs of algorithms
        self._equation_spans: dict[int, tuple[ca.MX, dict]] = {}  # id(residual) -> (it, its equation's span)

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
            var_kind, _ = kind_of(v.get("variability"))
            caus_kind, _ = kind_of(v.get("causality"))
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
                    evaluate=(kind == "parameter" and str(v.get("evaluate")) == "True"
                              and str(v.get("evaluate_refused")) != "True"),
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
                if not is_number(val):
                    raise CompileError(f"array size of {name!r} in {self.model} is not a constant")
                out.append(int(val))
        return tuple(out)

    # -------------------------------------------------------- value lookup
    def _element(self, sv: ScalarVar, node: Any, *, once: bool = False) -> Value:
        """Evaluate an attribute node (start/binding) for one scalar of an array. With *once* (where only
        the number is wanted: start values), the node is translated once for all the scalars of its
        array (an IF97 ``h_start`` of a pipe's n segments was translated n times)."""
        val = self._translated_once(node) if once else self.expr(node)
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

    def _translated_once(self, node: Any) -> Value:
        memo: dict[int, tuple[Any, Value]] = self.__dict__.setdefault("_once", {})
        hit = memo.get(id(node))
        if hit is None or hit[0] is not node:
            hit = memo[id(node)] = (node, self.expr(node))
        return hit[1]

    def structural_value(self, sv: ScalarVar) -> Any:
        if sv.value is not None:
            return sv.value
        if sv.name in self._evaluating:
            raise CompileError(f"parameter {sv.name!r} in {self.model} depends on itself")
        self._evaluating.add(sv.name)
        try:
            node = sv.binding_node if sv.binding_node is not None else sv.start_node
            defined = initial_definition(self.flat, sv.name) if sv.fixed is False and sv.binding_node is None else None
            if defined is not None:  # an Integer/Boolean parameter (fixed = false) that an initial equation gives
                val: Any = self.expr(defined)
            elif node is None:
                val = False if sv.type == BOOLEAN else 0
            else:
                val = self._element(sv, node)
            if not is_number(val) and sv.kind != "constant":  # bound to Real parameters (structural_params)
                val = evaluated_from_parameters(self, sv, val) if sv.type != REAL else val
            if not is_number(val):
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
        if is_number(value):
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
            val = 0.0 if node is None else self.numeric(self._element(sv, node, once=True), f"value of {sv.name!r}")
        finally:
            self._evaluating.discard(sv.name)
        sv.value = val
        return val

    def ref(self, name: str, subs: list[Any], env: dict[str, Value] | None) -> Value:
        if env is not None and name in env:
            val = env[name]
            if subs:
                return arr.subscript(val, [self._subscript(s, val, k, env, read=True) for k, s in enumerate(subs)],
                                     repr(name))
            return val
        if env is not None and not subs:  # a record of the function, kept field by field (.records)
            rec = records.gather(name, env, env.__getitem__)
            if rec is not None:
                return rec
        if name == "time":
            return self.time
        if name not in self.vars:
            ordinal = (self.flat.get("enum_literal_ordinals") or {}).get(name)
            if ordinal is not None and not subs:  # an enumeration literal is its ordinal (MLS 4.9.5)
                return int(ordinal)
            # component_ref names of array elements of components come as "a[2].b"
            rec = None if subs else records.gather(name, self.vars, lambda n: self.ref(n, [], None))
            if rec is not None:  # a record variable used whole: the record of its fields' variables
                return rec
            if any(v.startswith(name + ".") for v in self.vars):  # a record's fields are variables
                raise self.unsupported(
                    f"a record variable used whole (`{name}`, e.g. a medium's ThermodynamicState set from "
                    "or passed to a function that returns or takes the record; its fields are variables of "
                    "their own)",
                    rf"\b{re.escape(name.rsplit('.', 1)[-1])}\b", span=self._span)
            size = self.record_arrays().get(name)
            if size is not None:  # an array of records or components used whole or sliced (.record_arrays)
                return self.path_value(self._subscripted_paths(element_paths(name, size), subs, env, name))
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
            picks = [self._subscript(s, shape_only, k, env, read=True) for k, s in enumerate(subs)]
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
        if sv.evaluate and sv.fixed is not False:
            value = self._evaluated_parameter(sv)
            if value is not None:
                return value
        return sv.sym

    def _without_vanished_derivatives(self, residuals: list[tuple[ca.MX, str]],
                                      init_residuals: list[tuple[ca.MX, str]]) -> list[tuple[ca.MX, str]]:
        """The residuals without the derivatives that an evaluated parameter equal to 0 multiplies
        away (``i = C*der(v)`` with ``C = 0`` is ``i = 0``; a transistor's charge terms ``(if .. then
        Cjc*.. else Cjc*..)*der(vbc)`` with ``Cjc = 0``): each residual that has a derivative is
        expanded into CasADi's scalar graph, whose construction folds ``0*x`` and ``if c then 0 else
        0`` to 0, and a derivative it no longer depends on is removed; a variable whose derivative no
        equation keeps is no state. A residual that cannot be expanded (a rootfinder, an external
        function) keeps what it has."""
        ders = {d.name() for d in self.der_placeholders.values()}
        continuous = {sv.sym.name(): sv.sym for sv in self.scalars.values() if sv.kind == "continuous"}
        residuals = list(residuals)
        # a variable that an equation v = e sets to 0 (e folding to 0 once expanded, e.g. a junction
        # capacitance Cjc*powlin(..) with Cjc = 0) is 0 in the other equations
        zero: dict[int, ca.MX] = {}  # the equation that sets it -> the variable
        while True:  # until no equation sets another one to 0 (Capcjc = 0, then cbc = Taur*.. + Capcjc)
            found = self._zero_settings(residuals, continuous, ders, zero)
            if not found:
                break
            zero.update(found)
            set_zero = list(found.values())
            residuals = [(r if k in zero else ca.substitute([r], set_zero, [ca.MX(0)] * len(set_zero))[0], o)
                         for k, (r, o) in enumerate(residuals)]
        out = []
        for r, origin in residuals:
            syms = ca.symvar(r)
            if any(s.name() in ders for s in syms):
                try:
                    f = ca.Function("vanish", syms, [r]).expand()
                except RuntimeError:
                    out.append((r, origin))
                    continue
                sx = f.sx_in()
                e = f(*sx)
                gone = [m for m, x in zip(syms, sx) if m.name() in ders and not ca.depends_on(e, x)]
                if gone:
                    r = ca.substitute([r], gone, [ca.MX(0)] * len(gone))[0]
            out.append((r, origin))
        used = {s.name() for r, _ in list(out) + list(init_residuals) for s in ca.symvar(r)}
        for name, d in list(self.der_placeholders.items()):
            if d.name() not in used:
                log.info("%s: %s is no state: its derivative is multiplied by an evaluated parameter equal "
                         "to 0 wherever it appears", self.model, name)
                del self.der_placeholders[name]
        return out

    @staticmethod
    def _zero_settings(residuals: list[tuple[ca.MX, str]], continuous: dict[str, ca.MX], ders: set[str],
                       known: dict[int, ca.MX]) -> dict[int, ca.MX]:
        """{equation index: variable} of the equations (not in *known*) that, expanded, depend on one
        continuous variable only, linearly, and hold where it is 0 (and not where it is 1)."""
        found: dict[int, ca.MX] = {}
        for k, (r, origin) in enumerate(residuals):
            if k in known:
                continue
            syms = ca.symvar(r)
            if not any(m.name() in continuous for m in syms) or any(m.name() in ders for m in syms):
                continue
            try:
                f = ca.Function("vanish", syms, [r]).expand()
            except RuntimeError:
                continue
            sx = f.sx_in()
            e = f(*sx)
            left = [(m, x) for m, x in zip(syms, sx) if ca.depends_on(e, x)]
            if len(left) == 1 and left[0][0].name() in continuous and not ca.depends_on(
                    ca.jacobian(e, left[0][1]), left[0][1]):  # linear in it: 0 is its one solution
                g = ca.Function("g", [left[0][1]], [e])
                if float(g(0.0)) == 0 and float(g(1.0)) != 0:
                    found[k] = left[0][0]
        return found

    def _evaluated_parameter(self, sv: ScalarVar) -> float | None:
        """The value of a Real parameter with ``annotation(Evaluate = true)`` where its binding is a
        number (else None: it stays a parameter). The equations then see the number, as tools that
        evaluate such parameters do, so that e.g. a capacitor with ``C = 0`` (MSL
        ``Analog.Examples.HeatingNPN_NORGate``: ``final C = CapVal``, ``CapVal = 0`` evaluated) has
        ``i = 0`` and its voltage is no state."""
        if sv.name not in self._evaluated:
            self._evaluated[sv.name] = None
            node = sv.binding_node if sv.binding_node is not None else sv.start_node
            if node is not None:
                try:
                    val = self._element(sv, node)
                except CompileError:
                    val = None
                if is_number(val):
                    self._evaluated[sv.name] = float(val)
        return self._evaluated[sv.name]

    def _subscript(self, sub: Any, value: Value, k: int, env: dict[str, Value] | None, read: bool = False) -> Value:
        """One subscript: an Integer, a vector of Integers, or None for ``:``; where an element is
        *read*, also an Integer variable (:func:`.arrays.subscript` selects on its value).

        ``end`` comes from the flat model as ``size(a, k)`` of the array itself.
        """
        kind, body = kind_of(sub)
        if kind == "Index":
            return int(body["value"])
        if kind == "Colon":
            return None
        if kind == "Expr":
            val = self.expr(body["expr"], env)
            if arr.is_array(val):
                if not all(is_number(v) for v in val.ravel()):
                    raise CompileError(f"non-constant array subscript `{expression_text(body['expr'])}` "
                                       f"in {self.model}")
                return val
            if read and isinstance(val, ca.MX) and val.is_scalar():
                return val
            if not is_number(val):
                raise self.unsupported(
                    f"subscript with a variable index `{expression_text(body['expr'])}`",
                    detail="indices must be parameters or constants",
                )
            return int(round(float(val)))
        raise self.unsupported(f"array subscript {kind!r}")

    # ------------------------------------------------------------ translate
    def translate(self) -> ExplicitModel:
        check_flat(self.flat, self.model, self.location)  # constants: bound, to constant expressions
        self.collect_variables()
        params, calculated, calc_eqs, computed, init_residuals = self._parameters()
        residuals = self._model_residuals(calc_eqs)
        if any(v == 0 for v in self._evaluated.values()):
            residuals = self._without_vanished_derivatives(residuals, init_residuals)
        states = [self.scalars[n] for n in self.der_placeholders]
        state_names = set(self.der_placeholders)
        algebraics = self._initial_residuals(init_residuals, state_names)
        unknowns = self._unknowns(states, algebraics, calculated)
        # events: the equations of discrete variables are solved at events only (.events); between
        # events the continuous equations see them (and pre(v) = v) held
        discrete = [sv for sv in self.scalars.values() if sv.kind == "discrete"]
        # (calculated parameters are unknowns of the continuous equations but known at events)
        time_varying = {u.name() for u in unknowns} - {sv.name for sv in calculated}
        residuals, discrete_residuals = self._split_discrete(residuals, time_varying, discrete)
        discrete_residuals += self._discrete_defs
        init_residuals, discrete_initial = self._split_discrete(init_residuals, time_varying, discrete,
                                                                initial=True)
        blocks, residuals, states, algebraics, unknowns, optional_init = self._sorted_blocks(
            residuals, states, algebraics, calculated, calc_eqs, unknowns)
        # a variable with fixed = true that became a state (.flat_systems._preferred_states) starts at its start
        started = {f"start value of {s.name} (fixed = true)" for s in states if s.fixed is True}
        init_residuals = [(r, o) for r, o in init_residuals if o not in started]
        self._parameter_names = {sv.name for sv in params}
        self._loop_memory: list = []  # (.flat_systems._rootfinder)
        assignments, loop_sizes, torn_sizes = self._solve_blocks(blocks, residuals, unknowns, algebraics + calculated)
        self._model_system = (residuals, unknowns)  # (.flat_systems._whole_initial_solution)
        init_residuals = with_initial_derivatives(self, init_residuals, states, (blocks, residuals, unknowns))
        log.debug("%s: %d blocks, algebraic loops (equations, tearing variables): %s",
                  self.model, len(blocks), torn_sizes)
        events = self._event_system(discrete, discrete_residuals, discrete_initial)
        initial = None
        preferred = self.preferred_starts(states)
        if init_residuals or computed or optional_init or preferred:
            initial = self._initial_system(init_residuals, states, computed, assignments, optional_init, preferred)
            if not initial.unknowns:
                initial = None
        asserts = self._unique_asserts()
        params, unused = self._used_parameters(params, computed, assignments, asserts, initial, events)
        return ExplicitModel(
            asserts=asserts, initial=initial, events=events, discrete=discrete,
            name=self.model, time=self.time, parameters=params, calculated=calculated, unused_parameters=unused,
            inputs=[sv for sv in self.scalars.values() if sv.kind == "input"],
            states=states, algebraics=algebraics, derivative=dict(self.der_placeholders),
            assignments=assignments, n_loops=len(loop_sizes), loop_sizes=loop_sizes, torn_sizes=torn_sizes,
            loop_memory=list(self._loop_memory),
        )

    def _parameters(self) -> tuple[list[ScalarVar], list[ScalarVar], list[tuple[ca.MX, str]], list[ScalarVar],
                                   list[tuple[ca.MX, str]]]:
        """The Real parameters sorted: (tunable, calculated, the calculated ones' binding equations,
        those with ``fixed = false`` solved at initialisation, their initial equations). A tunable
        parameter's value does not depend on other parameters; its start value is evaluated here."""
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
            val = self._element(sv, node, once=True)  # (a binding: no event, asserts recorded once)
            if is_number(val) or (isinstance(val, ca.MX) and not ca.symvar(val)):
                params.append(sv)
            else:
                calculated.append(sv)
                calc_eqs.append((sv.sym - val, f"binding of parameter {sv.name}"))
        for sv in computed:  # the start value is the guess; the binding (if any) is an initial equation
            sv.value = 0.0 if sv.start_node is None else self.numeric(
                self._element(sv, sv.start_node, once=True), f"start value of parameter {sv.name!r}")
        for sv in params:
            self.parameter_start(sv)
        return params, calculated, calc_eqs, computed, init_residuals

    def _model_residuals(self, calc_eqs: list[tuple[ca.MX, str]]) -> list[tuple[ca.MX, str]]:
        """The model's equations as (residual, origin): calculated parameters' bindings, the equation
        section, variables' binding equations, algorithm sections, when-equations; asserts recorded."""
        residuals: list[tuple[ca.MX, str]] = list(calc_eqs)
        check_lost_der_equations(self.flat, self.source, self.model, self.libraries)
        for eq in self.flat.get("equations", []):
            origin = origin_text(eq.get("origin"))
            val = self.expr(eq["residual"])
            for r in (val.ravel() if isinstance(val, np.ndarray) else [val]):
                if is_number(r):
                    if abs(float(r)) > 0:
                        raise CompileError(f"equation {origin} in {self.model} reduces to {r} = 0")
                    continue
                residuals.append((r, origin))
                if isinstance(eq.get("span"), dict):
                    self._equation_spans[id(r)] = (r, eq["span"])
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
        return residuals

    def _initial_residuals(self, init_residuals: list[tuple[ca.MX, str]], state_names: set[str]) -> list[ScalarVar]:
        """Add the initial equations and initial algorithms to *init_residuals* (and ``v = start`` for
        an algebraic variable with ``fixed = true``); return the algebraic variables."""
        # der(v) of a variable no equation of the model differentiates: its value is built once the
        # model is causalised (.initial_derivatives); kept with the span of the first equation using it
        self._initial_ders: dict[str, tuple[ca.MX, Any]] = {}
        for eq in self.flat.get("initial_equations") or []:
            origin = f"initial equation {self._where(eq.get('origin'))}"
            val = self.expr(eq["residual"])
            span = eq.get("span") if isinstance(eq.get("span"), dict) else None
            for name in [n for n in self.der_placeholders if n not in state_names]:
                self._initial_ders.setdefault(name, (self.der_placeholders[name], span))
            for r in (val.ravel() if isinstance(val, np.ndarray) else [val]):
                if is_number(r):
                    if abs(float(r)) > 0:
                        raise CompileError(f"{origin} in {self.model} reduces to {r} = 0")
                    continue
                init_residuals.append((r, origin))
                if isinstance(eq.get("span"), dict):
                    self._equation_spans[id(r)] = (r, eq["span"])
        for section in self.flat.get("initial_algorithms") or []:
            init_residuals.extend(self.algorithm_residuals(section, initial=True))
        for name in [n for n in self.der_placeholders if n not in state_names]:  # (or an initial algorithm's)
            span = self._initial_ders[name][1] if name in self._initial_ders else None
            self._initial_ders[name] = (self.der_placeholders.pop(name), span)
        algebraics = [sv for sv in self.scalars.values() if sv.kind == "continuous" and sv.name not in state_names]
        for sv in algebraics:  # fixed = true on a variable that is not a state: an initial equation v = start
            if sv.fixed is True and sv.start_node is not None:
                init_residuals.append((sv.sym - self._element(sv, sv.start_node), f"start value of {sv.name} "
                                       "(fixed = true)"))
        return algebraics

    def _unknowns(self, states: list[ScalarVar], algebraics: list[ScalarVar],
                  calculated: list[ScalarVar]) -> list[ca.MX]:
        """The continuous equations' unknowns: the states' derivatives, the algebraic variables, the
        calculated parameters."""
        unknowns: list[ca.MX] = [self.der_placeholders[s.name] for s in states]
        return unknowns + [sv.sym for sv in algebraics] + [sv.sym for sv in calculated]

    def _sorted_blocks(self, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar],
                       algebraics: list[ScalarVar], calculated: list[ScalarVar],
                       calc_eqs: list[tuple[ca.MX, str]], unknowns: list[ca.MX]) -> tuple[
                           Any, list[tuple[ca.MX, str]], list[ScalarVar], list[ScalarVar], list[ca.MX],
                           list[tuple[ca.MX, str]]]:
        """The equations matched to the unknowns and sorted into blocks (.causalize); a structurally
        singular system goes to index reduction (.index), which may change the residuals, the states,
        the algebraic variables and the unknowns and add optional initial equations."""
        position = {u.name(): i for i, u in enumerate(unknowns)}
        incidence = []
        for r, _origin in residuals:
            incidence.append(sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position}))
        optional_init: list[tuple[ca.MX, str]] = []
        try:
            blocks = blt(incidence, len(unknowns))
        except StructuralError as exc:
            # a DAE of higher index: differentiate the constraints and choose the states (.index), those
            # the model prefers if they can be
            preferred = self._preferred_states(residuals, states, algebraics, calculated, calc_eqs)
            if preferred is not None:
                residuals, states, algebraics, unknowns, blocks, optional_init = preferred
                return blocks, residuals, states, algebraics, unknowns, optional_init
            reduced = self._reduce_index(residuals, states, algebraics, calculated, calc_eqs)
            if reduced is None:
                raise CompileError(self._structural_message(exc, residuals, [u.name() for u in unknowns])) from None
            residuals, states, optional_init = reduced
            state_names = {s.name for s in states}
            algebraics = [sv for sv in self.scalars.values()
                          if sv.kind == "continuous" and sv.name not in state_names]
            unknowns = self._unknowns(states, algebraics, calculated)
            position = {u.name(): i for i, u in enumerate(unknowns)}
            incidence = [sorted({position[s.name()] for s in ca.symvar(r) if s.name() in position})
                         for r, _origin in residuals]
            try:
                blocks = blt(incidence, len(unknowns))
            except StructuralError as exc2:
                raise CompileError(self._structural_message(exc2, residuals, [u.name() for u in unknowns])) from None
            return blocks, residuals, states, algebraics, unknowns, optional_init
        preferred = self._preferred_states(residuals, states, algebraics, calculated, calc_eqs)
        if preferred is not None:
            residuals, states, algebraics, unknowns, blocks, optional_init = preferred
        return blocks, residuals, states, algebraics, unknowns, optional_init

    def _solve_blocks(self, blocks: Any, residuals: list[tuple[ca.MX, str]], unknowns: list[ca.MX],
                      guessed: list[ScalarVar]) -> tuple[list[tuple[ca.MX, ca.MX]], list[int], list[tuple[int, int]]]:
        """Each block solved: explicitly where a scalar block is linear in its unknown, else torn
        and handed to a Newton rootfinder from the start values of *guessed* (0 where none can be
        evaluated). Returns the assignments in order, the tearing sizes and (equations, tearing
        variables) of each algebraic loop."""
        guess = {}
        for sv in guessed:
            node = sv.start_node
            try:
                guess[sv.name] = 0.0 if node is None else self.numeric(self._element(sv, node, once=True), "start value")
            except CompileError:
                guess[sv.name] = 0.0
        # a variable the model prefers as a state (a medium's p and T) is torn before one with a
        # type's start value (a density's 1): its start value is the modeller's guess (.flat_systems._tear)
        preferred = {n for n, select in self._state_select().items() if select in ("Always", "Prefer")}
        assignments: list[tuple[ca.MX, ca.MX]] = []
        loop_sizes: list[int] = []
        torn_sizes: list[tuple[int, int]] = []
        for k, block in enumerate(blocks):
            res = [residuals[i][0] for i in block.equations]
            unk = [unknowns[j] for j in block.unknowns]
            if len(unk) == 1:
                sol = solve_scalar_linear(res[0], unk[0])
                if sol is not None:
                    assignments.append((unk[0], sol))
                    continue
            tears, solved, residual = self._tear(res, unk, guess, preferred)
            loop_sizes.append(len(tears))
            torn_sizes.append((len(unk), len(tears)))
            if not tears:  # every equation solved explicitly in turn (cannot happen for an SCC, kept safe)
                assignments.extend(solved)
                continue
            sols = self._torn_rootfinder(k, residual, tears, solved, [guess.get(u.name(), 0.0) for u in tears])
            assignments.extend(zip(tears, sols))
            assignments.extend(solved)
        return assignments, loop_sizes, torn_sizes

    def _used_parameters(self, params: list[ScalarVar], computed: list[ScalarVar],
                         assignments: list[tuple[ca.MX, ca.MX]], asserts: list[Assertion],
                         initial: Any, events: Any) -> tuple[list[ScalarVar], list[str]]:
        """(the parameters some expression of the model uses, the names of the others).

        A parameter that no equation uses (e.g. one that only sets start values) would be a
        tunable parameter with no effect: the FMU's states start from fixed numbers, so it is
        not exported; set the state's own start value instead."""
        exprs = [e for _, e in assignments] + [a.condition for a in asserts]
        if initial is not None:
            exprs += initial.residual
        if events is not None:
            exprs += [e for _, e in events.updates] + [e for _, e in events.reinits] + events.indicators
            exprs += [x for smp in events.samples for x in (smp.start, smp.interval)]
        used = {s.name() for s in ca.symvar(ca.vertcat(*exprs))} if exprs else set()
        used |= {sv.name for sv in computed}
        unused = [sv.name for sv in params if sv.name not in used]
        return [sv for sv in params if sv.name in used], unused
