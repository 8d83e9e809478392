"""The embedded backend: rumoca flattens, CasADi builds and exports, gcc compiles.

Needs only PyPI packages (rumoca, casadi, fmpy) and a C compiler. It produces
FMI 3.0 model-exchange FMUs. See :mod:`.flatten` for what Modelica it accepts.
"""
from __future__ import annotations

import difflib
import importlib.metadata
import logging
import os
import pickle
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from .. import config
from ..errors import CompileError, UnsupportedConstructError, did_you_mean
from . import function_locals, inner_defaults
from .expandable import drop_absent_members
from .fmi_export import export_fmu
from .flatten import FlatTranslator
from .init_check import refuse_failed_homotopy_start
from .frontend import FlatCache, FrontendTree, build_tree, may_be_pruned
from .library import index_for, locate, model_files, one_look, resolve_libraries
from .rewrite import frontend_bytes
from .semantics import check_source
from .source import Location, ModelicaSource, class_names, experiment_settings

log = logging.getLogger(__name__)


def _diagnostics(raw: list[tuple[str, str, int | None]]) -> list[str]:
    """rumoca's error diagnostics (from the worker) as ``file:line: message``."""
    found: list[str] = []
    for file, text, line in raw:
        # rumoca's message carries the exact position as ╭─[file:line:col]
        pos = re.search(r"\[([^\]\[]+?):(\d+):(\d+)\]", text)
        where = f"{pos.group(1)}:{pos.group(2)}:{pos.group(3)}" if pos else f"{file}:{line}"
        summary = next((ln.strip(" ×") for ln in text.splitlines() if "×" in ln), text.splitlines()[0])
        found.append(f"{where}: {summary.strip()}")
    return found


def _without_paths(text: str) -> str:
    """*text* without file positions (``[/a/b.mo:3:4]``, ``/a/b.mo:3``): words in a directory name
    (``test_when_...``) are not what the message says."""
    text = re.sub(r"\[[^\]\[]*?\.mo(?::\d+)*\]", " ", text)
    return re.sub(r"(?:/[^\s:,()\[\]]+)+\.mo(?::\d+)*", " ", text)


_MENTIONED = (  # (the embedded path compiles when, pre, edge, sample, reinit: a refusal naming them is rumoca's)
    ("external", "external function", r"\bexternal\b"),
    ("clock", "clocked equations", r"\bClock\b"),
)


def _mentioned_construct(message: str, source: ModelicaSource, model: str,
                         libraries: tuple[Path, ...] = ()) -> UnsupportedConstructError | None:
    """rumoca refused a construct the embedded path does not support either: say where it is
    (in the model's own file or a class it uses, never elsewhere in the package)."""
    low = _without_paths(message).lower()
    for needle, construct, pattern in _MENTIONED:
        if needle in low:
            locs = locate(source, model, pattern, libraries=libraries)
            if locs:
                where = ", ".join(str(loc) for loc in locs)
                return UnsupportedConstructError(
                    f"unsupported Modelica construct: {construct} at {where} "
                    f"(rumoca: {message.splitlines()[0][:300]})"
                )
    return None


_CLASS_DECL = r"\b(?:model|block|class|connector|record|package|function|type)\s+{name}\b"
_POSITION = re.compile(r"\[([^\]\[]+?\.mo):(\d+):\d+\]")
_IMPLICIT_RANGE = "indices require an explicit range"


def _frontend_limit(message: str, diags: list[str], source: ModelicaSource,
                    model: str, libraries: tuple[Path, ...] = ()) -> UnsupportedConstructError | None:
    """rumoca said it does not support something (not that the model is wrong): refuse naming
    the construct in rumoca's words and where it stands in the model's own files."""
    low = _without_paths(message).lower()
    first = _without_paths(message.splitlines()[0])
    nested = re.search(r"unresolved import: '([\w.]+)'", first)
    if _IMPLICIT_RANGE in low:
        construct = "for-loop without an explicit range (for i loop ...)"
        pattern: str | None = r"\bfor\s+\w+\s+loop\b"
    elif nested and nested.group(1).startswith(model + "."):
        construct = (f"import of {nested.group(1)}, a class nested in the model itself "
                     "(not supported by the rumoca front end)")
        pattern = rf"\bimport\s+{re.escape(nested.group(1))}\b"
    elif "unsupported" in low:
        detail = first[low.index("unsupported"):].strip()
        construct = f"{detail[len('unsupported '):]} (not supported by the rumoca front end)"
        op = (re.search(r"operator `(\w+)`", detail)
              or re.search(r"\b(der|delay|pre|edge|sample|reinit|spatialDistribution|cardinality)\b", detail))
        pattern = (rf"\b{re.escape(op.group(1))}\s*\(" if op
                   else r"\bfor\s+\w+\s*(?:[),]|in\s*\{)" if "comprehension" in detail
                   else r"\bfor\b" if "for-equation" in detail
                   else r"\bif\b" if "if-equation" in detail
                   else r"\bfor\s+\w+\s+in\b" if re.search(r"\brange\b", detail)
                   else r"\balgorithm\b" if "algorithm" in detail else None)
    else:
        return None
    allowed = {str(f) for f in model_files(source, model, libraries=libraries)}
    where = [f"{f}:{n}" for f, n in _POSITION.findall(message) if f in allowed]
    where += [d.split(": ", 1)[0].rsplit(":", 1)[0] for d in diags
              if d.split(":", 1)[0] in allowed and ("indices require" in d or "unsupported" in d.lower())]
    if not where and pattern:
        where = [str(loc) for loc in locate(source, model, pattern, libraries=libraries)]
    if not where:  # the first occurrence of a name rumoca quotes (`f`, `findValue`) in the model's own code
        for name in re.findall(r"`([A-Za-z_]\w*)`", first):
            found = locate(source, model, rf"\b{re.escape(name)}\b", limit=1, libraries=libraries)
            if found:
                where = [str(found[0])]
                break
    if not where:  # nothing to point at: at least the line that declares the model
        decl = locate(source, model, _CLASS_DECL.format(name=re.escape(model.rsplit(".", 1)[-1])), limit=1, libraries=libraries)
        where = [f"{decl[0]} (the model's declaration; the front end gave no position)"] if decl else []
    at = f" at {', '.join(dict.fromkeys(where))}" if where else ""
    return UnsupportedConstructError(
        f"unsupported Modelica construct in {model}: {construct}{at}. The embedded backend cannot compile "
        "it; use --backend openmodelica where omc is installed, or rewrite the model")


def _own_position(first: str, source: ModelicaSource, model: str, libraries: tuple[Path, ...] = ()) -> str:
    """For a front-end message without a position: where the first name it quotes (`x`) stands
    in the model's own class, else the line that declares the model (`` (... at file:line)``)."""
    for name in re.findall(r"`([A-Za-z_]\w*)`", first):
        found = locate(source, model, rf"(?<![\w.]){re.escape(name)}\b", limit=1, own=True, libraries=libraries)
        if found:
            return f" (`{name}` at {found[0]} in {model}; the front end gave no position)"
    decl = locate(source, model, _CLASS_DECL.format(name=re.escape(model.rsplit(".", 1)[-1])), limit=1, own=True, libraries=libraries)
    return f" ({model} is declared at {decl[0]}; the front end gave no position)" if decl else ""


_NAMED_IN_MESSAGE = (
    # (what rumoca's message names, where that stands in the code)
    (r"\binitial algorithm", r"\binitial\s+algorithm\b"),
    (r"\balgorithm sections?\b", r"(?<!initial )\balgorithm\b"),
    (r"\b([A-Za-z_]\w*)\(\)", r"\b{0}\s*\("),
)


def _named_position(first: str, source: ModelicaSource, model: str, libraries: tuple[Path, ...] = ()) -> str:
    """Where the construct rumoca's message names (``initial algorithm``, ``delay()``, ...) stands
    in the model's own class (its own file), or "" when the message names none or it is not there."""
    for said, where in _NAMED_IN_MESSAGE:
        found = re.search(said, first)
        if found is None:
            continue
        pattern = where.format(*(re.escape(g) for g in found.groups()))
        locs = locate(source, model, pattern, limit=3, own=True, libraries=libraries)
        if locs:
            return ", ".join(dict.fromkeys(str(loc) for loc in locs))
    return ""


def _frontend_version() -> str:
    try:
        return importlib.metadata.version("rumoca")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - rumoca is a dependency
        return "unknown version"


@dataclass(frozen=True)
class FrontendGap:
    """A valid construct the front end (rumoca) refuses with a message that does not say so.

    Attributes
    ----------
    construct:
        The construct as the README's refused list names it.
    message:
        Regular expression on rumoca's message; its named groups fill ``{...}`` in the patterns.
    where:
        Regular expression (a template) for the construct in the model's code: the refusal
        names the model only where it is found, and the line it is found on.
    requires:
        Optional second template that must also match in the model's code.
    readme:
        The words the README's list of refused constructs uses for it (a test checks they are there).
    """

    construct: str
    message: str
    where: str
    requires: str | None = None
    readme: str = ""


_ENUM_TAIL = r"(?:[\w]+\.)*(?P<enum>\w+)"
FRONTEND_GAPS: tuple[FrontendGap, ...] = (
    FrontendGap("array dimension or for-range over Boolean (`b[Boolean]`, `for i in false:true`)",
                r"could not be evaluated: \[Expression\(\w+\)\]|expected `Boolean`, found `Integer`",
                r"\[\s*Boolean\s*\]|\bin\s+(?:Boolean\b|false\s*:\s*true\b)",
                readme="Boolean or enumeration array dimensions and for-ranges"),
    FrontendGap("array dimension or for-range over an enumeration type (`x[E]`, `for e in E`)",
                rf"expected `{_ENUM_TAIL}`, found `Integer`",
                r"\[\s*{enum}\s*\]|\bin\s+{enum}\b", requires=r"\btype\s+{enum}\s*=\s*enumeration\b",
                readme="Boolean or enumeration array dimensions and for-ranges"),
    FrontendGap("for-loop over an array of Strings (`for s in {\"a\", \"b\"}`)",
                r"expected `Integer`, found `String`",
                r"\bfor\s+\w+\s+in\s*\{",
                readme="for-loops over Strings"),
    FrontendGap("Integer array bound to `ones(...)` or `zeros(...)` (the front end types them Real)",
                r"expected `Integer`, found `Real`",
                r"\bInteger\b[^;]*=\s*(?:ones|zeros)\s*\(",
                readme="Integer arrays bound to `ones`/`zeros`"),
    FrontendGap("logical operator (`and`, `or`, `not`) on arrays",
                r"(?:unevaluable array dimensions for '|unresolved component dimension for )(?P<var>\w+)'?: "
                r"(?:colon dimension|:)",
                r"\b{var}\s*\[[\s:,]*\]\s*=[^;]*\b(?:and|or|not)\b",
                readme="logical operators on arrays"),
    FrontendGap("flexible array size `:` taken from a function result (`x[:] = f(...)`)",
                r"(?:unevaluable array dimensions for '|unresolved component dimension for )(?P<var>\w+)'?: "
                r"(?:colon dimension|:)",
                r"(?m)^(?!\s*(?:input|output)\b)[^\n]*?\b{var}\s*\[[\s:,]*\]",
                readme="flexible `:` sizes taken from a function result"),
    FrontendGap("an array dimension given by an Integer parameter that a function computes "
                "(`parameter Integer ns = f(...)`, `Real buf[ns]`: the front end does not evaluate the call)",
                r"unevaluable array dimensions for '(?:\w+\.)*(?P<var>\w+)': dimension expression could not be "
                r"evaluated: \[Expression\((?P<dim>\w+)\)\]",
                r"\b{var}\s*\[\s*{dim}\s*\]", requires=r"\bparameter\s+Integer\s+{dim}\s*=\s*[\w.]+\s*\(",
                readme="array dimensions given by a parameter that a function computes"),
    FrontendGap("`cross`/`skew` of Integer vectors",
                r"ToDae.*expression type mismatch: expected Real, found Integer",
                r"\b(?:cross|skew)\s*\(",
                readme="`cross`/`skew` of Integer vectors"),
    FrontendGap("`end` inside a subscript of the binding of a flexible-size array (`y[:] = x[1:end-1]`)",
                r"ToDae.*expression shape mismatch",
                r"\[[\s:,]*\]\s*=[^;]*\[[^\[\];]*\bend\b",
                readme="`end` in subscripts of such a binding"),
    FrontendGap("`cat(3, ...)`: concatenation along the third dimension",
                r"ToDae.*expression shape mismatch",
                r"\bcat\s*\(\s*3\s*,",
                readme="`cat(3, ...)`"),
    FrontendGap("Integer array concatenated from `zeros(...)` or `ones(...)` blocks (`[-1, zeros(1, 2)]`)",
                r"ToDae.*expression shape mismatch",
                r"\bInteger\b[^;]*=\s*(?:\[|cat\s*\()[^;]*\b(?:zeros|ones)\s*\(",
                readme="Integer arrays concatenated from `zeros`/`ones`"),
    FrontendGap("call of a function whose inputs and defaults come through `extends`",
                r"invalid call of function `(?:\w+\.)*(?P<fn>\w+)`: input `\w+` has no argument and no default",
                r"\b{fn}\s*\(", requires=r"\bfunction\s+{fn}\s+extends\b",
                readme="function inputs inherited through `extends`"),
    FrontendGap("partial application that binds inputs before the free ones (`function f(a = ...)`)",
                r"type mismatch: expected `[\w.]+`, found `[\w.]+`",
                r"\bfunction\s+[\w.]+\s*\(",
                readme="partial application binding leading inputs or of a functional input"),
    FrontendGap("partial application of a functional input inside a function (`function integrand(y = x)`)",
                r"must be a function name or a partial application",
                r"\bfunction\s+[\w.]+\s*\(",
                readme="partial application binding leading inputs or of a functional input"),
    FrontendGap("partial derivative of a function (`function f_x = der(f, x)`)",
                r"function-selection identity",
                r"\bfunction\s+\w+\s*=\s*der\s*\(",
                readme="partial derivatives of functions"),
    FrontendGap("`flow` prefix on a component outside a connector",
                r"component '(?P<var>\w+)' cannot have 'flow' prefix outside a connector",
                r"\bflow\s+[\w.]+\s+{var}\b",
                readme="`flow` outside connectors"),
    FrontendGap("`inStream` of a field of a stream variable of record type",
                r"inStream\(\) is only allowed on stream variables",
                r"\binStream\s*\(", requires=r"\bstream\s+(?!Real\b|Integer\b)[A-Za-z_][\w.]*\s+\w+",
                readme="`inStream` of record stream variables"),
    FrontendGap("`String()` of an enumeration value",
                r"String conversion currently requires .*found Enumeration",
                r"\bString\s*\(",
                readme="`String()` of an enumeration"),
    FrontendGap("a Boolean or Integer output connected to several inputs, one of them an element of an "
                "input array (`connect(p.y, t.trigger)` and `connect(p.y, m.u[1])`: the front end cannot "
                "orient the connection equation between two of the inputs)",
                r"element assignments must cover a discrete coordinate exactly once",
                r"\bconnect\s*\(\s*([\w.]+)\s*,\s*[\w.\[\]]+\s*\)[^;]*;(?:[^;]*;){0,40}?"
                r"\s*connect\s*\(\s*\1\s*,\s*[\w.]+\[\s*\d+\s*\]\s*\)",
                readme="a discrete output connected to several inputs, one of them an element of an input array"),
    FrontendGap("`cardinality()`",
                r"unresolved Flat reference `[^`]*cardinality|cardinality\(\) may only be used",
                r"\bcardinality\s*\(",
                readme="`cardinality()`"),
    FrontendGap("a constant or function of a package reached through a component or a replaceable package "
                "(`Medium.…`) that the front end leaves unresolved",
                r"unresolved Flat reference `(?:[\w]+\.)*(?P<leaf>\w+)`",
                r"(?<![\w])(?:\w+\.)*{leaf}\b",
                readme="constants and functions of packages reached through replaceable packages"),
)
"""Valid constructs the front end refuses without saying it does not support them (found on the
Modelica compliance suite); each is listed in the README's compile section."""


def _frontend_gap(message: str, source: ModelicaSource, model: str,
                  libraries: tuple[Path, ...] = ()) -> UnsupportedConstructError | None:
    """rumoca refused a valid construct with a type or shape error: name the construct and the
    line where it stands in the model's own code, saying that the front end does not support it."""
    for gap in FRONTEND_GAPS:
        found = re.search(gap.message, message, re.S)
        if found is None:
            continue
        names = {k: re.escape(v) for k, v in found.groupdict().items() if v is not None}

        def fill(template: str) -> str:
            for key, value in names.items():
                template = template.replace("{" + key + "}", value)
            return template

        if gap.requires and not locate(source, model, fill(gap.requires), limit=1, libraries=libraries):
            continue
        locs = locate(source, model, fill(gap.where), limit=3, libraries=libraries)
        if not locs:
            continue
        where = ", ".join(dict.fromkeys(str(loc) for loc in locs))
        return UnsupportedConstructError(
            f"unsupported Modelica construct in {model}: {gap.construct} at {where}. The front end "
            f"(rumoca {_frontend_version()}) does not support it (rumoca: {message.splitlines()[0][:200]}); "
            "use --backend openmodelica where omc is installed, or rewrite the model")
    return None


COMPONENT_SIZED_ARRAY = ("an array of components whose size is a parameter of another component "
                         "(`FixedHeatFlow[pipe2.nNodes] heat2`)")
"""The README's words for the construct :func:`_component_sized_array` names."""
_SHORT_OF_EQUATIONS = re.compile(r"unbalanced model: \d+ equations, \d+ unknowns \(balance = -\d+")
_SIZED_BY_COMPONENT = re.compile(r"(?<![\w.])[A-Za-z_][\w.]*\s*\[\s*(?P<comp>[A-Za-z_]\w*)\.[A-Za-z_]\w*\s*\]"
                                 r"\s*(?P<name>[A-Za-z_]\w*)\s*[(;]")


def _component_sized_array(message: str, source: ModelicaSource, model: str,
                           libraries: tuple[Path, ...] = ()) -> UnsupportedConstructError | None:
    """rumoca 0.10.2 sizes the variables of an array of components whose size is a parameter of
    another component (``FixedHeatFlow[pipe2.nNodes] heat2`` in ``BranchingDynamicPipes``) but
    instantiates the class's equations once, so the model comes back "unbalanced", short by the
    size minus one per equation of the class (a top-level ``parameter Integer N`` as the size is
    read right). Named where the model's own class declares such an array of a component it
    declares too; any other shortfall stays rumoca's message."""
    if not _SHORT_OF_EQUATIONS.search(message):
        return None
    index = index_for(source, libraries)
    info = index.classes.get(model)
    if info is None:
        return None
    code = index.code(info)
    for found in _SIZED_BY_COMPONENT.finditer(code):
        comp = re.escape(found.group("comp"))
        if not re.search(rf"(?<![\w.])[A-Za-z_][\w.]*\s+{comp}\s*[(;\[]", code):
            continue  # a package's constant (``Medium.nX``), not a component's parameter
        where = Location(*index.location(info, found.start()))
        return UnsupportedConstructError(
            f"unsupported Modelica construct in {model}: {COMPONENT_SIZED_ARRAY} at {where} "
            f"(`{found.group('name')}`): the front end (rumoca {_frontend_version()}) instantiates the "
            f"class's equations once for the whole array (rumoca: {message.splitlines()[0][:200]}); give "
            "the size as a parameter of the model itself, use --backend openmodelica where omc is installed, "
            "or rewrite the model")
    return None


FILL_OF_ARRAY = "`fill` of an array (`fill(C, nPorts)`)"
"""The README's words for the construct :func:`_fill_of_array` names."""
_FILL = re.compile(r"(?<![\w.])fill\s*\(\s*(?P<name>[A-Za-z_]\w*)\s*(?P<sub>\[[^\[\]]*\])?\s*,")


def _fill_of_array(message: str, source: ModelicaSource, model: str,
                   libraries: tuple[Path, ...] = ()) -> UnsupportedConstructError | None:
    """rumoca 0.10.2 refuses ``fill(c, n)`` of an array ``c`` ("expression shape mismatch": ``Real
    c[1] = {time}; Real cc[2, 1] = fill(c, 2);``), as every ``Modelica.Fluid`` source writes
    ``ports.C_outflow = fill(C, nPorts)``, which stops ``RoomCO2``'s trace substance. Named where a
    class the model uses fills a slice (``X[1:n]``) or a name it or a base declares with dimensions."""
    if "expression shape mismatch" not in message:
        return None
    index = index_for(source, libraries)
    for name in index.used_classes(model):
        info = index.classes[name]
        code = index.own_code(info, annotations=False)
        for found in _FILL.finditer(code):
            sub, var = found.group("sub"), re.escape(found.group("name"))
            array = sub is not None and ":" in sub
            if sub is None:
                declared = rf"(?<![\w.])[A-Za-z_][\w.]*\s+{var}\s*\["
                array = any(re.search(declared, index.own_code(index.classes[c], annotations=False))
                            for c in index.ancestors(name))
            if array:
                where = Location(*index.location(info, found.start()))
                return UnsupportedConstructError(
                    f"unsupported Modelica construct in {model}: {FILL_OF_ARRAY} at {where}: the front end "
                    f"(rumoca {_frontend_version()}) does not support it (rumoca: {message.splitlines()[0][:200]}); "
                    "use --backend openmodelica where omc is installed, or rewrite the model")
    return None


_NESTED_REFERENCE = re.compile(r"reference to non-constant variable '(\w+)' from a lexically nested class")
NESTED_EXTENDS = "`extends` of a class declared inside the extending class itself"
"""The README's words for the construct :func:`_nested_extends` names."""


def _nested_extends(message: str, source: ModelicaSource, model: str,
                    libraries: tuple[Path, ...] = ()) -> UnsupportedConstructError | None:
    """rumoca 0.10.2 says a nested class refers to a non-constant of its enclosing class (MLS 5.3.1)
    where a class extends a class declared inside itself (the MSL's ``MassWithStopAndFriction``
    extends its own ``PartialFrictionWithStop``): the nested class's references to its own
    components are then taken for the enclosing class's. Modelica finds them in the nested class
    (MLS 5.3.1 looks there first), so the model is valid: where a class the model uses does that,
    refuse naming the ``extends``, its file and line (else the message stands as an error)."""
    found = _NESTED_REFERENCE.search(message)
    if found is None:
        return None
    index = index_for(source, libraries)
    for name in index.used_classes(model):
        info = index.classes[name]
        own = index.children.get(name, {})
        for base in info.extends:
            if "." in base or base not in own:
                continue
            at = re.search(rf"\bextends\s+{re.escape(base)}\b", index.own_code(info))
            where = f"{index.location(info, at.start())[0]}:{index.location(info, at.start())[1]}" if at \
                else f"{info.file}:{info.line}"
            return UnsupportedConstructError(
                f"unsupported Modelica construct in {model}: {NESTED_EXTENDS} (`extends {base}` in {name}, "
                f"{base} declared inside {name}) at {where}. The front end (rumoca {_frontend_version()}) "
                f"takes {base}'s references to its own components (`{found.group(1)}`) for {name}'s and "
                "refuses them (rumoca: a reference to a non-constant variable from a lexically nested class); "
                "use --backend openmodelica where omc is installed, or rewrite the model")
    return None


FRONTEND_TIMEOUT = config.setting("frontend_timeout").default
"""Seconds the front end (rumoca load + flatten) may take before it counts as hung;
``TRACKINGBOX_FRONTEND_TIMEOUT`` overrides it."""


def _signal_name(code: int) -> str:
    try:
        return signal.Signals(-code).name
    except ValueError:
        return f"signal {-code}"


_ASSERT_COUNTED = re.compile(r"unbalanced model: (\d+) equations, (\d+) unknowns \(balance = [1-9]")


def run_frontend(source: ModelicaSource, model: str, libraries: tuple[Path, ...] = (),
                 validate: tuple[Path, ...] | None = None, parse_error: bool = False) -> dict:
    """Run rumoca's load + flatten (or, given *validate*, its diagnostics of those files)
    in a worker process and return the worker's answer.

    rumoca reads a front-end tree (:mod:`.frontend`): a copy of the files the model can reach,
    as rumoca should read them; should the flatten fail on a name the copy may have left out,
    it is repeated on the whole source and libraries. A flattened model is kept in the flat
    cache and reused while every file of its tree is unchanged (``"cached": True`` in the answer).

    A worker that dies (segmentation fault, abort, stack overflow) or outlives
    :data:`FRONTEND_TIMEOUT` raises :class:`CompileError` naming the model and
    the signal; the tool itself never goes down with it.
    """
    timeout = float(config.get("frontend_timeout"))
    with tempfile.TemporaryDirectory(prefix="tbx-frontend-") as tmp:
        req, res = Path(tmp) / "request.pickle", Path(tmp) / "result.pickle"
        if validate is not None:
            return _validate(source, model, validate, parse_error, Path(tmp), req, res, timeout)
        cache = FlatCache() if FlatCache.enabled() else None
        index = index_for(source, libraries)
        for prune in (True, False):
            tree = build_tree(source, model, libraries, Path(tmp) / ("pruned" if prune else "full"), prune=prune,
                              index=index)
            key = tree.cache_key(model)
            if cache is not None:
                flat = cache.get(key)
                if flat is not None:
                    log.debug("front end: %s from the flat cache (%s)", model, key[:12])
                    return {"ok": True, "flat": flat, "cached": True}
            request = {"mode": "flatten", "entry": str(tree.entry), "model": model,
                       "stack_mb": config.get("frontend_stack_mb"),
                       "roots": [str(r) for r in tree.roots] if tree.roots else None}
            answer = tree.rename(_run_worker(request, req, res, source, model, timeout))
            if answer["ok"] and tree.pruned:
                answer = _with_inner_values(answer, source, model, libraries, index, Path(tmp), request, req, res,
                                            timeout)
            if not answer["ok"] and answer.get("kind") == "rumoca":
                answer = _with_undefined_locals(answer, source, model, libraries, index, Path(tmp), request, req,
                                                res, timeout, prune)
            if answer["ok"]:
                if cache is not None:
                    cache.put(key, answer["flat"])  # (a retry's under the first tree's key: it is its reading)
                return answer
            if (tree.pruned and answer.get("kind") == "rumoca"
                    and _ASSERT_COUNTED.search(answer["message"] or "")):
                # rumoca counts an assert reached by evaluating a parameter's binding as an equation
                # (.rewrite.computed_parameter_bindings): again with such parameters computed at
                # initialisation; the first answer stands if that does not help
                first = answer
                retry = build_tree(source, model, libraries, Path(tmp) / "computed", prune=True,
                                   index=index, computed=True)
                if retry.digest == tree.digest:  # no such parameter: nothing to try
                    return first
                log.info("front end: %s unbalanced (%s); again with parameters bound to calls of asserting "
                         "functions computed at initialisation", model, answer["message"].splitlines()[0][:200])
                request = {**request, "entry": str(retry.entry),
                           "roots": [str(r) for r in retry.roots] if retry.roots else None}
                again = retry.rename(_run_worker(request, req, res, source, model, timeout))
                if again["ok"]:
                    if cache is not None:
                        cache.put(key, again["flat"])  # under the first tree's key: the retry is its reading
                    return again
                return first
            if not (tree.pruned and answer.get("kind") == "rumoca" and may_be_pruned(answer["message"], index, tree)):
                return answer
            log.info("front end: %s failed on the files its lookup reaches (%s); again on the whole "
                     "libraries", model, answer["message"].splitlines()[0][:200])
        return answer


UNDEFINED_RETRIES = 12
"""Most functions given undefined bindings for their partly assigned locals, one retry each."""


def _with_undefined_locals(answer: dict, source: ModelicaSource, model: str, libraries: tuple[Path, ...], index,
                           tmp: Path, request: dict, req: Path, res: Path, timeout: float, prune: bool) -> dict:
    """*answer*, a refusal by rumoca of a function local that an if-statement assigns on some branches
    only, flattened again with that function's such locals bound to "undefined" (:mod:`.function_locals`),
    and so on for each function refused next; the last refusal where a function cannot be so read."""
    done: set[str] = set()
    while len(done) < UNDEFINED_RETRIES:
        hit = function_locals.REFUSAL.search(answer.get("message") or "")
        function = function_locals.function_named(index, hit.group(1)) if hit else None
        if function is None or function in done or not function_locals.bindings(index, function):
            return answer
        done.add(function)
        log.info("front end: %s refused %s's local %s (assigned on some branches only); again with its such "
                 "locals undefined where unassigned", model, function, hit.group(2))
        tree = build_tree(source, model, libraries, tmp / f"undefined{len(done)}", prune=prune, index=index,
                          undefined=frozenset(done))
        again = {**request, "entry": str(tree.entry), "roots": [str(r) for r in tree.roots] if tree.roots else None}
        answer = tree.rename(_run_worker(again, req, res, source, model, timeout))
        if answer["ok"] and tree.pruned:
            answer = _with_inner_values(answer, source, model, libraries, index, tmp, again, req, res, timeout,
                                        frozenset(done))
    return answer


def _with_inner_values(answer: dict, source: ModelicaSource, model: str, libraries: tuple[Path, ...], index,
                       tmp: Path, request: dict, req: Path, res: Path, timeout: float,
                       undefined: frozenset[str] = frozenset()) -> dict:
    """*answer* flattened again with the values its flat model gives the inner modifications that name
    other parameters (:mod:`.inner_defaults`: rumoca 0.10.2 reads an outer parameter from its class's
    default); *answer* itself where there are none or the second flatten fails."""
    reached = index.frontend_files(model) if model in index.classes else None
    names = inner_defaults.pending(index, model, reached) if reached else set()
    roots = {r.name.removesuffix(".mo") for r in index.roots}
    values = inner_defaults.flat_values(answer["flat"], names, roots) if names else {}
    if not values:
        return answer
    log.info("front end: %s again with the inner modifications %s", model,
             ", ".join(f"{k} = {v}" for k, v in sorted(values.items())))
    tree = build_tree(source, model, libraries, tmp / "inner", prune=True, index=index, inner_values=values,
                      undefined=undefined)
    request = {**request, "entry": str(tree.entry), "roots": [str(r) for r in tree.roots] if tree.roots else None}
    again = tree.rename(_run_worker(request, req, res, source, model, timeout))
    return again if again["ok"] else answer


def _validate(source: ModelicaSource, model: str, validate: tuple[Path, ...], parse_error: bool, tmp: Path,
              req: Path, res: Path, timeout: float) -> dict:
    """rumoca's diagnostics of *validate* (and of every file of the source after a parse error), each
    read as rumoca reads it in a compile (a rewritten copy where :mod:`.rewrite` changes it)."""
    renames: list[tuple[str, str]] = []

    def readable(files) -> list[str]:
        out = []
        for f in files:
            f = Path(f)
            data = frontend_bytes(f)
            if data is None:
                out.append(str(f))
                continue
            copy = tmp / "validate" / str(len(renames)) / f.name
            copy.parent.mkdir(parents=True, exist_ok=True)
            copy.write_bytes(data)
            renames.append((str(copy), str(f)))
            out.append(str(copy))
        return out

    request = {"mode": "validate", "parse_error": parse_error, "model": model,
               "stack_mb": config.get("frontend_stack_mb"),
               "validate": readable(validate), "validate_all": readable(source.files) if parse_error else []}
    answer = _run_worker(request, req, res, source, model, timeout)
    return FrontendTree(entry=tmp, roots=None, renames=sorted(renames, key=lambda r: -len(r[0]))).rename(answer)


def _run_worker(request: dict, req: Path, res: Path, source: ModelicaSource, model: str,
                timeout: float) -> dict:
    req.write_bytes(pickle.dumps(request))
    cmd = [sys.executable, str(Path(__file__).with_name("_frontend.py")), str(req), str(res)]
    log.debug("front end: %s", " ".join(cmd))
    # rumoca would load every library on MODELICAPATH itself: the tree already holds what is needed
    env = {k: v for k, v in os.environ.items() if k != "MODELICAPATH"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True, env=env)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise CompileError(f"the Modelica front end did not finish on {model} from {source.entry} "
                           f"within {timeout:g} s (set TRACKINGBOX_FRONTEND_TIMEOUT to wait longer)") from None
    tail = out.decode("utf-8", "replace").strip()[-300:]
    if proc.returncode < 0:
        raise CompileError(f"the Modelica front end crashed on {model} from {source.entry} "
                           f"({_signal_name(proc.returncode)}; rumoca died, e.g. on an expression "
                           f"nested too deeply or a very long sum)") from None
    if proc.returncode != 0 or not res.is_file():
        raise CompileError(f"the Modelica front end crashed on {model} from {source.entry} "
                           f"(exit status {proc.returncode}{': ' + tail if tail else ''})") from None
    return pickle.loads(res.read_bytes())


def _missing_library(message: str, missing: dict[str, str], model: str) -> CompileError | None:
    """The front end failed while a top-level package the model's classes use is in no library: say
    which (the package the front end's message names, else the first one missing)."""
    if not missing or not re.search(r"unresolved|not found|unknown", _without_paths(message), re.I):
        return None
    names = [(q[0] or q[1]).split(".", 1)[0] for q in re.findall(r"'([A-Za-z_][\w.]*)'|`([A-Za-z_][\w.]*)`", message)]
    first = next((n for n in names if n in missing), next(iter(missing)))
    others = [n for n in missing if n != first]
    also = f" (also not found: {', '.join(others)})" if others else ""
    return CompileError(
        f"`{first}` is used by {missing[first]} but not found: pass --library DIR (the {first} package "
        f"directory, or the directory that holds it) or set MODELICAPATH{also}")


def flatten(source: ModelicaSource, model: str, libraries: tuple[Path, ...] = (),
            missing: dict[str, str] | None = None) -> dict:
    """Run rumoca on *model*; raise :class:`CompileError` with file:line diagnostics.

    *missing*: top-level packages the model uses that no library holds (name -> where it is
    used, :func:`.library.resolve_libraries`); a failure on one of them names the library."""
    answer = run_frontend(source, model, libraries)
    if answer["ok"]:
        return answer["flat"]
    message = answer["message"]
    if missing:
        lost = _missing_library(message, missing, model)
        if lost is not None:
            raise lost
    if answer["kind"] != "rumoca":
        raise CompileError(f"rumoca failed on {model!r} from {source.entry}: {message}")
    first = message.splitlines()[0] if message else "rumoca error"
    try:  # diagnostics of the model's own files (and of every file for a syntax error elsewhere)
        raw = run_frontend(source, model, libraries, validate=model_files(source, model, libraries=libraries),
                           parse_error="parse" in message.lower())["diagnostics"]
    except CompileError:
        raw = []
    diags = _diagnostics(raw)
    nested = (_nested_extends(message, source, model, libraries)
              or _component_sized_array(message, source, model, libraries))
    if nested is not None:
        raise nested
    if "resolve/parse failed" in first or not diags:
        if not diags and ("not found" in first.lower() or "resolve/parse failed" in first):
            known = class_names(source)
            if model not in known:
                raise CompileError(f"class {model!r} not found in {source.entry}"
                                   f"{did_you_mean(model, known)} (classes are named with their "
                                   f"package, e.g. Pkg.Sub.Model)")
            raise CompileError(f"cannot compile {model!r} from {source.entry}: {first}"
                               f"{_own_position(first, source, model, libraries)}")
    construct = (_mentioned_construct(message, source, model, libraries)
                 or _frontend_limit(message, diags, source, model, libraries)
                 or _frontend_gap(message, source, model, libraries)
                 or _fill_of_array(message, source, model, libraries))
    if construct is not None:
        raise construct
    detail = ("\n  " + "\n  ".join(diags)) if diags else ""
    named = _named_position(first, source, model, libraries)
    if named:  # the construct rumoca names, where it stands in the model's own class, comes first
        detail = f" (at {named}){detail}"
    elif not diags and not _POSITION.search(message):  # e.g. ToDae type errors: at least the class
        detail = _own_position(first, source, model, libraries)
    raise CompileError(f"cannot compile {model!r} from {source.entry}: {first}{detail}")


def _refuse_absent(source: ModelicaSource, model: str, libraries: tuple[Path, ...]) -> None:
    """Refuse a model name the library index shows is not there, before the front end parses
    the whole library to say so (a misspelt MSL name took about a minute).

    Only where the index is sure: the longest prefix of *model* that is a class, and every class
    it extends (transitively), are short of no resolved base, so no inherited member can supply
    the missing part. Otherwise the front end decides, as before."""
    idx = index_for(source, libraries)
    parts = model.split(".")
    found = idx.top(parts[0])
    if found is None:
        return  # an unknown top-level package is the missing-library message's to name
    for depth, part in enumerate(parts[1:], 1):
        inner = idx.member(found, part)
        if inner is None:
            break
        found = inner
    else:
        return
    seen: set[str] = set()
    todo = [found]
    while todo:
        cls = todo.pop()
        if cls in seen:
            continue
        seen.add(cls)
        info = idx.classes.get(cls)
        bases = idx.bases(cls)
        if info is None or info.short or info.class_extends or len(bases) < len(info.extends):
            return  # something the index cannot follow: leave it to the front end
        todo.extend(bases)
    same = difflib.get_close_matches(model, idx.by_simple.get(parts[-1], ()), n=3, cutoff=0.0)
    hint = (" (did you mean " + ", ".join(map(repr, same)) + "?)") if same else did_you_mean(model, idx.classes)
    raise CompileError(f"class {model!r} not found in {source.entry}: {'.'.join(parts[:depth])} has no class "
                       f"{parts[depth]!r}"
                       f"{hint} (classes are named with their package, e.g. Pkg.Sub.Model)")


def compile_embedded(source: ModelicaSource, model: str, output: Path,
                     libraries: tuple[Path, ...] = (), parameters: str = "tunable") -> tuple[str, int, int]:
    """Compile with the embedded toolchain; returns (log, n_states, n_parameters).

    *parameters* ``"fixed"`` declares the parameters ``fixed`` in the FMU (:func:`.fmi_export.declare_fixed`).
    The library files are looked at once for the whole compilation (:func:`.library.one_look`).
    """
    with one_look():
        return _compile_embedded(source, model, output, libraries, parameters)


def _compile_embedded(source: ModelicaSource, model: str, output: Path,
                      libraries: tuple[Path, ...], parameters: str) -> tuple[str, int, int]:
    t0 = time.perf_counter()
    libraries, missing = resolve_libraries(source, model, libraries)
    _refuse_absent(source, model, libraries)
    flat = flatten(source, model, libraries, missing)
    if flat.get("is_partial"):
        raise CompileError(f"{model!r} is a partial class and cannot be compiled")
    class_type = str(flat.get("class_type", "")).lower()
    if class_type in ("package", "function", "connector", "record", "type"):
        raise CompileError(f"{model!r} is a {class_type}, not a model or block")
    check_source(source, model)  # invalid Modelica the front end accepted (.semantics)
    absent = drop_absent_members(flat)  # unconnected members of expandable connectors (MLS 9.1.3)
    if absent:
        log.debug("%s: expandable-connector members nothing connects, not in the model: %s",
                  model, ", ".join(absent))
    t1 = time.perf_counter()
    translator = FlatTranslator(flat, source, model, libraries)
    em = translator.translate()
    t2 = time.perf_counter()
    settings = experiment_settings(source, model)
    build_log = export_fmu(em, translator, output, experiment=settings, fixed_parameters=parameters == "fixed")
    if em.initial is not None:  # homotopy(): rumoca keeps only its actual argument (.init_check)
        refuse_failed_homotopy_start(source, model, libraries, output)
    t3 = time.perf_counter()
    computed = set(em.initial.computed_parameters) if em.initial is not None else set()
    tunable = sum(1 for p in em.parameters if p.name not in computed)  # fixed = false ones are calculated
    summary = (
        f"{model}: {len(em.states)} states, {len(em.algebraics)} algebraic variables, "
        f"{tunable} tunable parameters"
        f"{f' and {len(computed)} computed at initialisation' if computed else ''}, {em.n_loops} algebraic loops "
        f"(equations -> tearing variables: {', '.join(f'{a}->{b}' for a, b in em.torn_sizes) or 'none'}); "
        f"flatten {t1 - t0:.2f} s, causalise {t2 - t1:.2f} s, export+cc {t3 - t2:.2f} s"
    )
    if em.unused_parameters:
        summary += ("\nnot exported (no equation uses them; they can only set start values, which the "
                    "FMU takes from the states' own start attributes): " + ", ".join(em.unused_parameters))
    log.info(summary)
    return summary + "\n" + build_log, len(em.states), tunable
