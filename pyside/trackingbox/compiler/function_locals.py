"""Function locals that an if-statement assigns on some of its branches only, given to the front end
with a binding that stands for "undefined".

In Modelica a function's local variable without a binding is undefined until a statement assigns it
(MLS 12.4.4); a program may assign it on some branches of an if-statement only and read it only where
it was assigned. MSL 4.0.0's ``IF97_Utilities.BaseIF97.Transport.cond_dTp`` (``thermalConductivity``
of ``Modelica.Media.Water``) sets ``region`` on the branches of ``p < data.PLIMIT4A`` but not on the
one that asserts, and ``delta``, ``g``, ... on one branch of ``industrialMethod == true`` only. rumoca
0.10.2 refuses every such local ("reads `region`, which only some branches of the conditional ...
define"; a record local "missing function value definition"), one at a time, and reads the same
function where each has a binding (measured on copies of ``cond_dTp``: ``tests/test_compiler_function_locals.py``).

:func:`patches` gives each such local, scalar and declared without a binding in a function the model
uses, the binding ``0.0/0.0`` (``integer(0.0/0.0)`` for an Integer, the record's constructor with
``0.0/0.0`` for each field for a record of scalar Real and Integer fields): the IEEE quiet NaN, the
value an undefined Real reads as. The embedded backend's inliner reads exactly that binding of a
local as NaN (:func:`.flat_statements.undefined_binding`), so a branch that assigns the local gives
its value as before, and a path that reads it unassigned gives NaN, which stops the simulation,
rather than a number. A local of another type (Boolean, String, an array, a record with other
fields) is left as written: rumoca's refusal stands, naming it. Lines are kept; byte offsets after an
edit shift.
"""
from __future__ import annotations

import logging
import re
from collections.abc import Callable
from pathlib import Path

log = logging.getLogger(__name__)

UNDEFINED_REAL = "0.0/0.0"
"""The binding that stands for an undefined Real (and, in ``integer(...)``, Integer) local."""

_TOKEN = re.compile(r":=|[A-Za-z_][\w.]*|\d+(?:\.\d*)?(?:[eE][-+]?\d+)?|\"[^\"]*\"|\S")
_SCALARS = {"Real": "Real", "Integer": "Integer"}
_PREFIXES = {"input", "output", "constant", "parameter", "discrete", "flow", "stream", "final",
             "replaceable", "redeclare", "outer", "inner", "import", "extends", "type", "record",
             "function", "model", "block", "package", "connector", "class", "annotation"}


# --- which locals: assigned on some branches of an if-statement, not before it ---------------------

def _condition_end(toks: list[str], i: int) -> int:
    """Index of the ``then`` that ends the condition starting at *i* (if-expressions inside skipped)."""
    depth = pending = 0
    while i < len(toks):
        t = toks[i]
        if t in "([{":
            depth += 1
        elif t in ")]}":
            depth -= 1
        elif depth == 0 and t == "if":
            pending += 1
        elif depth == 0 and t == "else" and pending:
            pending -= 1
        elif depth == 0 and t == "then" and not pending:
            return i
        i += 1
    return i


def _simple_statement(toks: list[str], i: int, defined: set[str]) -> int:
    """Skip the statement at *i* (to after its ``;``), adding what it assigns to *defined*."""
    depth = 0
    start = i
    while i < len(toks) and not (depth == 0 and toks[i] == ";"):
        if toks[i] in "([{":
            depth += 1
        elif toks[i] in ")]}":
            depth -= 1
        elif toks[i] == ":=" and depth == 0:
            head = toks[start:i]
            if head and head[0] == "(":  # (a, b) := f(...)
                names = [head[k] for k in range(1, len(head)) if head[k - 1] in "(," and head[k][0].isalpha()]
            else:
                names = head[:1]
            defined.update(n.split(".")[0] for n in names)
        i += 1
    return i + 1


def _statements(toks: list[str], i: int, defined: set[str], partial: set[str]) -> int:
    """Walk statements from *i* to the ``elseif``/``else``/``end`` that closes them."""
    while i < len(toks) and toks[i] not in ("elseif", "else", "end", "annotation", "external"):
        t = toks[i]
        if t in ("if", "when"):
            i = _if_statement(toks, i, defined, partial)
        elif t in ("for", "while"):
            depth = 0
            while i < len(toks) and not (depth == 0 and toks[i] == "loop"):
                depth += toks[i] in "([{"
                depth -= toks[i] in ")]}"
                i += 1
            i = _statements(toks, i + 1, set(defined), partial)  # a loop may run no time
            i += 3  # end for ;
        else:
            i = _simple_statement(toks, i, defined)
    return i


def _if_statement(toks: list[str], i: int, defined: set[str], partial: set[str]) -> int:
    keyword = toks[i]
    branches: list[set[str]] = []
    has_else = False
    i += 1
    while i < len(toks):
        i = _condition_end(toks, i)
        branch = set(defined)
        i = _statements(toks, i + 1, branch, partial)
        branches.append(branch)
        if i < len(toks) and toks[i] == ("elseif" if keyword == "if" else "elsewhen"):
            i += 1
            continue
        if i < len(toks) and toks[i] == "else":
            branch = set(defined)
            i = _statements(toks, i + 1, branch, partial)
            branches.append(branch)
            has_else = True
        break
    if not has_else:
        branches.append(set(defined))
    partial |= set().union(*branches) - set.intersection(*branches)
    defined |= set.intersection(*branches)
    return i + 3  # end if ;


def partially_assigned(code: str) -> set[str]:
    """The names that an if-statement of the algorithm sections of function text *code* (comments
    and strings blanked) assigns on some of its branches (a missing ``else`` counting as one that
    assigns nothing) and that no statement before it assigns on every path."""
    partial: set[str] = set()
    for m in re.finditer(r"\balgorithm\b", code):
        end = re.search(r"\b(?:algorithm|equation|protected|public|external)\b|\bend\s+[A-Za-z_]\w*\s*;\s*\Z",
                        code[m.end():])
        toks = _TOKEN.findall(code[m.end():m.end() + end.start()] if end else code[m.end():])
        _statements(toks, 0, set(), partial)
    return partial


# --- their declarations and bindings ---------------------------------------------------------------

def _scalar_kind(index, type_name: str, scope: str) -> str | None:
    """'Real' or 'Integer' where *type_name* (used in class *scope*) is one of them or a type
    derived from one, else None."""
    if type_name in _SCALARS:
        return _SCALARS[type_name]
    cls = index.lookup(type_name, scope)
    for _ in range(20):
        info = index.classes.get(cls) if cls else None
        if info is None or info.kind != "type":
            return None
        builtin = next((e for e in info.extends if e in _SCALARS), None)
        if builtin:
            return _SCALARS[builtin]
        bases = index.bases(cls)
        cls = bases[0] if len(bases) == 1 else None
    return None


_DECLARATION = re.compile(r"(?<![\w.])([A-Za-z_][\w.]*)\s+([A-Za-z_]\w*)\s*(\()?")


def _declarations(code: str) -> dict[str, tuple[str, int]]:
    """The components *code* declares without a binding, subscripts or a prefix such as input/constant:
    name -> (type name, offset just after the name)."""
    out: dict[str, tuple[str, int]] = {}
    head = re.split(r"\b(?:algorithm|equation)\b", code, maxsplit=1)[0]
    head = re.sub(r"\b(?:protected|public)\b", lambda m: ";" + " " * (len(m.group(0)) - 1), head)  # offsets kept
    for m in _DECLARATION.finditer(head):
        type_name, name = m.group(1), m.group(2)
        if type_name in _PREFIXES or name in _PREFIXES or type_name in ("end", "within"):
            continue
        before = re.search(r"([\w.]+|[;\"(])\s*$", head[:m.start()])
        if before is not None and before.group(1) not in (";", '"'):
            continue  # a prefix (input, constant, ...) or not at the start of a declaration
        end = m.end()
        if m.group(3):
            depth = 1
            while end < len(head) and depth:
                depth += (head[end] == "(") - (head[end] == ")")
                end += 1
        rest = head[end:end + 200].lstrip()
        if rest.startswith("=") or rest.startswith("[") or "[" in type_name:
            continue
        out[name] = (type_name, m.end(2))
    return out


def _record_binding(index, type_name: str, scope: str) -> str | None:
    """The record constructor call with every field undefined, for a record of scalar Real and
    Integer fields without bindings; None for any other class."""
    cls = index.lookup(type_name, scope)
    info = index.classes.get(cls) if cls else None
    if info is None or info.kind != "record" or info.short:
        return None
    fields: list[str] = []
    for name in index.ancestors(cls):
        anc = index.classes[name]
        text = index.own_code(anc, annotations=False)
        body = text[text.find("\n"):] if "\n" in text else ""
        declared = re.findall(r"(?<![\w.])[A-Za-z_][\w.]*\s+[A-Za-z_]\w*", re.sub(r"\bextends\b[^;]*;", ";", body))
        found = _declarations(body)
        if len(found) != len([d for d in declared if d.split()[0] not in _PREFIXES and d.split()[0] != "end"]):
            return None  # a field with a binding, a prefix or subscripts
        for field, (ftype, _) in found.items():
            kind = _scalar_kind(index, ftype, name)
            if kind is None:
                return None
            fields.append(f"{field}={UNDEFINED_REAL if kind == 'Real' else 'integer(' + UNDEFINED_REAL + ')'}")
    return f"{cls}({', '.join(fields)})" if fields else None


def bindings(index, function: str) -> list[tuple[int, str, str]]:
    """(line, local, binding text) for each local of *function* that :func:`partially_assigned`
    names and that can be given an undefined binding."""
    info = index.classes.get(function)
    if info is None or info.kind != "function" or info.short:
        return []
    code = index.own_code(info, annotations=False)
    if "algorithm" not in code:
        return []
    partial = partially_assigned(code)
    if not partial:
        return []
    out = []
    for name, (type_name, end) in _declarations(code).items():
        if name not in partial:
            continue
        kind = _scalar_kind(index, type_name, function)
        if kind == "Real":
            text = UNDEFINED_REAL
        elif kind == "Integer":
            text = f"integer({UNDEFINED_REAL})"
        else:
            text = _record_binding(index, type_name, function)
            if text is None:
                continue
        out.append((info.line + code.count("\n", 0, end), name, text))
    return out


REFUSAL = re.compile(r"`([\w.]+)` reads `(\w+)`, which only some branches of the conditional")
"""rumoca 0.10.2's refusal of a local assigned on some branches only: (the function's flat name, the local)."""


def function_named(index, flat_name: str) -> str | None:
    """The class with the algorithm of the function rumoca names *flat_name* (its full name, or its
    simple name for a function of a single file): a short class ``function f = g`` followed to g."""
    name = flat_name if flat_name in index.classes else None
    if name is None:
        found = [c for c, info in index.classes.items() if info.simple == flat_name and info.kind == "function"]
        name = found[0] if len(found) == 1 else None
    for _ in range(10):
        info = index.classes.get(name) if name else None
        if info is None or info.kind != "function":
            return None
        if not info.short:
            return name
        bases = index.bases(name)
        name = bases[0] if len(bases) == 1 else None
    return None


def patches(index, functions) -> dict[Path, Callable[[bytes], bytes]]:
    """Per file, the edit that gives the front end the bindings of :func:`bindings` for *functions*
    (full names; on the declaration's own line, a line not as the index read it left alone)."""
    found: dict[Path, list[tuple[int, str, str]]] = {}
    for name in sorted(functions):
        hits = bindings(index, name)
        if hits:
            found.setdefault(index.classes[name].file, []).extend(hits)
    out: dict[Path, Callable[[bytes], bytes]] = {}
    for file, edits in found.items():
        def patch(body: bytes, edits=edits, file=file) -> bytes:
            lines = body.split(b"\n")
            done = 0
            for line, local, text in edits:
                if line > len(lines):
                    continue
                src = lines[line - 1].decode("utf-8", errors="surrogateescape")
                m = re.search(rf"(?<![\w.])[A-Za-z_][\w.]*\s+{re.escape(local)}\b", src)
                if m is None:
                    continue
                end = m.end()
                if src[end:].lstrip()[:1] == "(":
                    end += len(src[end:]) - len(src[end:].lstrip())
                    depth = 0
                    for k in range(end, len(src)):
                        depth += (src[k] == "(") - (src[k] == ")")
                        if depth == 0:
                            end = k + 1
                            break
                    else:
                        continue  # the modification goes on over lines: left alone
                if src[end:].lstrip()[:1] not in ('"', ";", ""):
                    continue
                lines[line - 1] = (src[:end] + f" = {text}" + src[end:]).encode("utf-8", errors="surrogateescape")
                done += 1
            if done:
                log.debug("%s: %d function local(s) assigned on some branches only given an undefined "
                          "binding (.function_locals)", file, done)
            return b"\n".join(lines)
        out[file] = patch
    return out
