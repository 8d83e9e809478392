"""The embedded backend: rumoca flattens, CasADi builds and exports, gcc compiles.

Needs only PyPI packages (rumoca, casadi, fmpy) and a C compiler. It produces
FMI 3.0 model-exchange FMUs. See :mod:`.flatten` for what Modelica it accepts.
"""
from __future__ import annotations

import logging
import re
import time
from pathlib import Path

import rumoca

from ..errors import CompileError, UnsupportedConstructError, did_you_mean
from .fmi_export import export_fmu
from .flatten import FlatTranslator
from .source import ModelicaSource, class_names, experiment_settings, find_construct

log = logging.getLogger(__name__)


def _diagnostics(source: ModelicaSource, limit: int = 5) -> list[str]:
    """rumoca's error diagnostics for the source files, as ``file:line: message``."""
    found: list[str] = []
    for file in source.files:
        try:
            diags = rumoca.validate(str(file))
        except Exception:  # noqa: BLE001 - I/O failures: nothing to add
            continue
        for d in diags:
            if getattr(d, "level", "") != "error":
                continue
            text = str(getattr(d, "message", d))
            line = getattr(d, "line", None)
            # rumoca's message carries the exact position as ╭─[file:line:col]
            pos = re.search(r"\[([^\]\[]+?):(\d+):(\d+)\]", text)
            if pos:
                where = f"{pos.group(1)}:{pos.group(2)}:{pos.group(3)}"
            else:
                where = f"{file}:{line}"
            summary = next((ln.strip(" ×") for ln in text.splitlines() if "×" in ln), text.splitlines()[0])
            found.append(f"{where}: {summary.strip()}")
            if len(found) >= limit:
                return found
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


def _mentioned_construct(message: str, source: ModelicaSource) -> UnsupportedConstructError | None:
    """rumoca refused a construct the embedded path does not support either: say where it is."""
    low = message.lower()
    for needle, construct, pattern in _MENTIONED:
        if needle in low:
            locs = find_construct(source.files, pattern)
            if locs:
                where = ", ".join(str(loc) for loc in locs)
                return UnsupportedConstructError(
                    f"unsupported Modelica construct: {construct} at {where} "
                    f"(rumoca: {message.splitlines()[0][:300]})"
                )
    return None


def flatten(source: ModelicaSource, model: str, libraries: tuple[Path, ...] = ()) -> dict:
    """Run rumoca on *model*; raise :class:`CompileError` with file:line diagnostics."""
    roots = [str(source.root)] + [str(p) for p in libraries]
    session = rumoca.Session(roots=roots) if libraries else rumoca.Session()
    try:
        rmodel = session.load(str(source.entry), model=model)
    except rumoca.RumocaError as exc:
        first = str(exc).splitlines()[0]
        diags = _diagnostics(source)
        if "resolve/parse failed" in first or not diags:
            if not diags and ("not found" in first.lower() or "resolve/parse failed" in first):
                known = class_names(source)
                if model not in known:
                    raise CompileError(f"class {model!r} not found in {source.entry}"
                                       f"{did_you_mean(model, known)} (classes are named with their "
                                       f"package, e.g. Pkg.Sub.Model)") from None
                raise CompileError(f"cannot compile {model!r} from {source.entry}: {first}") from None
        construct = _mentioned_construct(str(exc), source)
        if construct is not None:
            raise construct from None
        detail = ("\n  " + "\n  ".join(diags)) if diags else ""
        raise CompileError(f"cannot compile {model!r} from {source.entry}: {first}{detail}") from None
    except Exception as exc:  # rumoca raises plain errors for some internal failures
        raise CompileError(f"rumoca failed on {model!r} from {source.entry}: {exc}") from None
    return rmodel.to_dict("flat")


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
    t1 = time.perf_counter()
    translator = FlatTranslator(flat, source, model)
    em = translator.translate()
    t2 = time.perf_counter()
    settings = experiment_settings(source, model)
    build_log = export_fmu(em, translator, output, experiment=settings)
    t3 = time.perf_counter()
    summary = (
        f"{model}: {len(em.states)} states, {len(em.algebraics)} algebraic variables, "
        f"{len(em.parameters)} tunable parameters, {em.n_loops} algebraic loops "
        f"(equations -> tearing variables: {', '.join(f'{a}->{b}' for a, b in em.torn_sizes) or 'none'}); "
        f"flatten {t1 - t0:.2f} s, causalise {t2 - t1:.2f} s, export+cc {t3 - t2:.2f} s"
    )
    if em.unused_parameters:
        summary += ("\nnot exported (no equation uses them; they can only set start values, which the "
                    "FMU takes from the states' own start attributes): " + ", ".join(em.unused_parameters))
    log.info(summary)
    return summary + "\n" + build_log, len(em.states), len(em.parameters)
