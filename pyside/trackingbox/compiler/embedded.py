"""The embedded backend: rumoca flattens, CasADi builds and exports, gcc compiles.

Needs only PyPI packages (rumoca, casadi, fmpy) and a C compiler. It produces
FMI 3.0 model-exchange FMUs. See :mod:`.flatten` for what Modelica it accepts.
"""
from __future__ import annotations

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
from .fmi_export import export_fmu
from .flatten import FlatTranslator
from .rewrite import frontend_bytes
from .semantics import check_source
from .source import ModelicaSource, class_names, experiment_settings, locate, model_files

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


_MENTIONED = (
    ("when", "when-clause", r"\bwhen\b"),
    ("pre(", "pre()", r"\bpre\s*\("),
    ("pre expression", "pre()", r"\bpre\s*\("),
    ("edge(", "edge()", r"\bedge\s*\("),
    ("sample(", "sample()", r"\bsample\s*\("),
    ("reinit", "reinit()", r"\breinit\s*\("),
    ("external", "external function", r"\bexternal\b"),
    ("clock", "clocked equations", r"\bClock\b"),
)


def _mentioned_construct(message: str, source: ModelicaSource, model: str) -> UnsupportedConstructError | None:
    """rumoca refused a construct the embedded path does not support either: say where it is
    (in the model's own file or a class it uses, never elsewhere in the package)."""
    low = message.lower()
    for needle, construct, pattern in _MENTIONED:
        if needle in low:
            locs = locate(source, model, pattern)
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
                    model: str) -> UnsupportedConstructError | None:
    """rumoca said it does not support something (not that the model is wrong): refuse naming
    the construct in rumoca's words and where it stands in the model's own files."""
    low = message.lower()
    first = message.splitlines()[0]
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
    allowed = {str(f) for f in model_files(source, model)}
    where = [f"{f}:{n}" for f, n in _POSITION.findall(message) if f in allowed]
    where += [d.split(": ", 1)[0].rsplit(":", 1)[0] for d in diags
              if d.split(":", 1)[0] in allowed and ("indices require" in d or "unsupported" in d.lower())]
    if not where and pattern:
        where = [str(loc) for loc in locate(source, model, pattern)]
    if not where:  # the first occurrence of a name rumoca quotes (`f`, `findValue`) in the model's own code
        for name in re.findall(r"`([A-Za-z_]\w*)`", first):
            found = locate(source, model, rf"\b{re.escape(name)}\b", limit=1)
            if found:
                where = [str(found[0])]
                break
    if not where:  # nothing to point at: at least the line that declares the model
        decl = locate(source, model, _CLASS_DECL.format(name=re.escape(model.rsplit(".", 1)[-1])), limit=1)
        where = [f"{decl[0]} (the model's declaration; the front end gave no position)"] if decl else []
    at = f" at {', '.join(dict.fromkeys(where))}" if where else ""
    return UnsupportedConstructError(
        f"unsupported Modelica construct in {model}: {construct}{at}. The embedded backend cannot compile "
        "it; use --backend openmodelica where omc is installed, or rewrite the model")


def _own_position(first: str, source: ModelicaSource, model: str) -> str:
    """For a front-end message without a position: where the first name it quotes (`x`) stands
    in the model's own class, else the line that declares the model (`` (... at file:line)``)."""
    for name in re.findall(r"`([A-Za-z_]\w*)`", first):
        found = locate(source, model, rf"(?<![\w.]){re.escape(name)}\b", limit=1, own=True)
        if found:
            return f" (`{name}` at {found[0]} in {model}; the front end gave no position)"
    decl = locate(source, model, _CLASS_DECL.format(name=re.escape(model.rsplit(".", 1)[-1])), limit=1, own=True)
    return f" ({model} is declared at {decl[0]}; the front end gave no position)" if decl else ""


_NAMED_IN_MESSAGE = (
    # (what rumoca's message names, where that stands in the code)
    (r"\binitial algorithm", r"\binitial\s+algorithm\b"),
    (r"\balgorithm sections?\b", r"(?<!initial )\balgorithm\b"),
    (r"\b([A-Za-z_]\w*)\(\)", r"\b{0}\s*\("),
)


def _named_position(first: str, source: ModelicaSource, model: str) -> str:
    """Where the construct rumoca's message names (``initial algorithm``, ``delay()``, ...) stands
    in the model's own class (its own file), or "" when the message names none or it is not there."""
    for said, where in _NAMED_IN_MESSAGE:
        found = re.search(said, first)
        if found is None:
            continue
        pattern = where.format(*(re.escape(g) for g in found.groups()))
        locs = locate(source, model, pattern, limit=3, own=True)
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
    FrontendGap("`cardinality()`",
                r"unresolved Flat reference|cardinality\(\) may only be used",
                r"\bcardinality\s*\(",
                readme="`cardinality()`"),
)
"""Valid constructs the front end refuses without saying it does not support them (found on the
Modelica compliance suite); each is listed in the README's compile section."""


def _frontend_gap(message: str, source: ModelicaSource, model: str) -> UnsupportedConstructError | None:
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

        if gap.requires and not locate(source, model, fill(gap.requires), limit=1):
            continue
        locs = locate(source, model, fill(gap.where), limit=3)
        if not locs:
            continue
        where = ", ".join(dict.fromkeys(str(loc) for loc in locs))
        return UnsupportedConstructError(
            f"unsupported Modelica construct in {model}: {gap.construct} at {where}. The front end "
            f"(rumoca {_frontend_version()}) does not support it (rumoca: {message.splitlines()[0][:200]}); "
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


def run_frontend(source: ModelicaSource, model: str, libraries: tuple[Path, ...] = (),
                 validate: tuple[Path, ...] | None = None, parse_error: bool = False) -> dict:
    """Run rumoca's load + flatten (or, given *validate*, its diagnostics of those files)
    in a worker process and return the worker's answer.

    A worker that dies (segmentation fault, abort, stack overflow) or outlives
    :data:`FRONTEND_TIMEOUT` raises :class:`CompileError` naming the model and
    the signal; the tool itself never goes down with it.
    """
    request = {
        "mode": "flatten" if validate is None else "validate",
        "parse_error": parse_error,
        "entry": str(source.entry),
        "model": model,
        "roots": ([str(source.root)] + [str(p) for p in libraries]) if libraries else None,
        "validate": [str(f) for f in validate or ()],
        "validate_all": [str(f) for f in source.files],
        "stack_mb": config.get("frontend_stack_mb"),
    }
    timeout = float(config.get("frontend_timeout"))
    with tempfile.TemporaryDirectory(prefix="tbx-frontend-") as tmp:
        req, res = Path(tmp) / "request.pickle", Path(tmp) / "result.pickle"
        # rumoca refuses a byte-order mark and loses some der() equations in for-loops: give it a copy
        # without the mark and with those equations protected (.rewrite; lines and offsets unchanged)
        if any(frontend_bytes(f) is not None for f in source.files):

            copy = _without_bom(source, Path(tmp) / "src")
            request["entry"] = str(copy / source.entry.relative_to(source.root))
            if request["roots"]:
                request["roots"] = [str(copy), *request["roots"][1:]]
            for key in ("validate", "validate_all"):
                request[key] = [str(copy / Path(f).relative_to(source.root)) for f in request[key]]
            answer = _run_worker(request, req, res, source, model, timeout)
            return _rename(answer, str(copy), str(source.root))
        return _run_worker(request, req, res, source, model, timeout)


def _without_bom(source: ModelicaSource, dest: Path) -> Path:
    """A copy of the package's files under *dest* as rumoca should read them (same relative
    paths; byte-order marks removed, der() equations in for-loops protected: :mod:`.rewrite`)."""
    for file in source.files:
        target = dest / file.relative_to(source.root)
        target.parent.mkdir(parents=True, exist_ok=True)
        data = frontend_bytes(file)
        target.write_bytes(file.read_bytes() if data is None else data)
    return dest


def _rename(obj: object, old: str, new: str) -> object:
    """*obj* with the path prefix *old* replaced by *new* in every string of messages and diagnostics."""
    if isinstance(obj, dict):
        return {k: (v if k == "flat" else _rename(v, old, new)) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_rename(v, old, new) for v in obj)
    if isinstance(obj, str):
        return obj.replace(old, new)
    return obj


def _run_worker(request: dict, req: Path, res: Path, source: ModelicaSource, model: str,
                timeout: float) -> dict:
    req.write_bytes(pickle.dumps(request))
    cmd = [sys.executable, str(Path(__file__).with_name("_frontend.py")), str(req), str(res)]
    log.debug("front end: %s", " ".join(cmd))
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True)
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


def flatten(source: ModelicaSource, model: str, libraries: tuple[Path, ...] = ()) -> dict:
    """Run rumoca on *model*; raise :class:`CompileError` with file:line diagnostics."""
    answer = run_frontend(source, model, libraries)
    if answer["ok"]:
        return answer["flat"]
    message = answer["message"]
    if answer["kind"] != "rumoca":
        raise CompileError(f"rumoca failed on {model!r} from {source.entry}: {message}")
    first = message.splitlines()[0] if message else "rumoca error"
    try:  # diagnostics of the model's own files (and of every file for a syntax error elsewhere)
        raw = run_frontend(source, model, libraries, validate=model_files(source, model),
                           parse_error="parse" in message.lower())["diagnostics"]
    except CompileError:
        raw = []
    diags = _diagnostics(raw)
    if "resolve/parse failed" in first or not diags:
        if not diags and ("not found" in first.lower() or "resolve/parse failed" in first):
            known = class_names(source)
            if model not in known:
                raise CompileError(f"class {model!r} not found in {source.entry}"
                                   f"{did_you_mean(model, known)} (classes are named with their "
                                   f"package, e.g. Pkg.Sub.Model)")
            raise CompileError(f"cannot compile {model!r} from {source.entry}: {first}"
                               f"{_own_position(first, source, model)}")
    construct = (_mentioned_construct(message, source, model) or _frontend_limit(message, diags, source, model)
                 or _frontend_gap(message, source, model))
    if construct is not None:
        raise construct
    detail = ("\n  " + "\n  ".join(diags)) if diags else ""
    named = _named_position(first, source, model)
    if named:  # the construct rumoca names, where it stands in the model's own class, comes first
        detail = f" (at {named}){detail}"
    elif not diags and not _POSITION.search(message):  # e.g. ToDae type errors: at least the class
        detail = _own_position(first, source, model)
    raise CompileError(f"cannot compile {model!r} from {source.entry}: {first}{detail}")


def compile_embedded(source: ModelicaSource, model: str, output: Path,
                     libraries: tuple[Path, ...] = ()) -> tuple[str, int, int]:
    """Compile with the embedded toolchain; returns (log, n_states, n_parameters)."""
    t0 = time.perf_counter()
    flat = flatten(source, model, libraries)
    if flat.get("is_partial"):
        raise CompileError(f"{model!r} is a partial class and cannot be compiled")
    class_type = str(flat.get("class_type", "")).lower()
    if class_type in ("package", "function", "connector", "record", "type"):
        raise CompileError(f"{model!r} is a {class_type}, not a model or block")
    check_source(source, model)  # invalid Modelica the front end accepted (.semantics)
    t1 = time.perf_counter()
    translator = FlatTranslator(flat, source, model)
    em = translator.translate()
    t2 = time.perf_counter()
    settings = experiment_settings(source, model)
    build_log = export_fmu(em, translator, output, experiment=settings)
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
