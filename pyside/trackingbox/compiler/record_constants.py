"""Fields of package constants of a record type, read by rumoca through their values.

rumoca 0.10.2 leaves every field of a record constant declared in a package unresolved
(``unresolved Flat reference `Modelica.Media.Air.MoistAir.dryair.R_s```), whether the field is
read in a function of the package, in its other constants or in a model, and whether the
constant is bound to another constant (``constant DataRecord dryair = SingleGasesData.Air``),
given a modification (``constant DataRecord Air(MM = 0.0289651159, R_s = 287.05...)``) or a
record constructor (measured on small packages, ``tests/test_compiler_record_constants.py``).
``Modelica.Media.Air.MoistAir`` reads ``dryair.R_s``, ``steam.R_s``, ``steam.MM`` and
``dryair.MM`` so, which stopped every example with moist air (``BranchingDynamicPipes``).

A constant's value is fixed where it is declared (MLS 4.4.4: a constant's binding is evaluated
where it stands), so such a field read by its simple name (``dryair.R_s``) in a class whose lookup
(MLS 5.3: the class itself, its bases, then the enclosing classes) finds the record constant has the
value that the constant's declaration gives the field. :func:`patches` replaces such a reference by
that value, on the same line, for the front end, where it can be sure of it:

* the constant's declaration gives the field a number literal in its modification, or binds the
  constant to another record constant (by name) for which that holds, at any depth;
* no class the model uses modifies an element of that name (``extends P(dryair = ...)``, a short
  class ``P(dryair = ...)`` or a named argument of that name): such a modification would give the
  package another value (``Modelica.Media.IdealGases.Common.SingleGasNasa``'s ``data``, which every
  gas package sets, stays as rumoca reads it, i.e. refused).

Anything else is left as written (rumoca's refusal stands, naming the construct).
"""
from __future__ import annotations

import logging
import re
from collections.abc import Callable
from pathlib import Path

from .library import KEYWORDS
from .modification_parse import _skip_expr

log = logging.getLogger(__name__)

_REF = re.compile(r"(?<![\w.])([A-Za-z_]\w*)\.([A-Za-z_]\w*)\b(?!\s*[.\[(])")
"""``a.b`` not part of a longer dotted name, not subscripted or called."""
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_PREFIXES = r"(?:(?:constant|parameter|input|output|final|discrete|flow|stream|inner|outer)\s+)*"
_MAX_DEPTH = 8


def own_text(index, cls: str, codes: dict[str, str]) -> str:
    """The comment-free own text of *cls* (annotations blanked), kept in *codes*."""
    if cls not in codes:
        codes[cls] = index.own_code(index.classes[cls], annotations=False)
    return codes[cls]


def declaration(index, cls: str, name: str, codes: dict[str, str], seen: set[str] | None = None):
    """The declaration of the component *name* in class *cls* or its bases: (class, match) with the
    groups ``prefix``, ``type`` and ``after`` (the character after the name), or None."""
    seen = set() if seen is None else seen
    if cls in seen or cls not in index.classes:
        return None
    seen.add(cls)
    pattern = re.compile(rf"(?<![\w.])(?P<prefix>{_PREFIXES})(?P<type>[A-Za-z_][\w.]*)\s*(?:\[[^\];]*\]\s*)?"
                         rf"(?<=[\s\]]){re.escape(name)}\s*(?:\[[^\];]*\]\s*)?(?P<after>[(=;])")
    for m in pattern.finditer(own_text(index, cls, codes)):
        if m.group("type") in KEYWORDS or m.group("type") in ("end", "import", "extends", "within"):
            continue
        return cls, m
    for base in index.bases(cls):
        found = declaration(index, base, name, codes, seen)
        if found is not None:
            return found
    return None


def _record_constant(index, scope: str, name: str, codes: dict[str, str]):
    """The record constant *name* as Modelica's lookup finds it from class *scope* (the class, its
    bases, then the enclosing classes up to an encapsulated one): (class, match), or None when the
    name is found as something else or not at all."""
    cur: str | None = scope
    while cur:
        found = declaration(index, cur, name, codes)
        if found is not None:
            cls, m = found
            if "constant" not in m.group("prefix").split():
                return None
            target = index.lookup(m.group("type"), cls)
            if target is None or index.classes[target].kind != "record":
                return None
            return found
        info = index.classes.get(cur)
        if info is None or info.encapsulated:
            return None
        cur = info.parent
    return None


def _closing(code: str, open_at: int) -> int:
    """Position of the parenthesis closing the one at *open_at* (the end of *code* if none)."""
    depth = 0
    for k in range(open_at, len(code)):
        if code[k] in "([{":
            depth += 1
        elif code[k] in ")]}":
            depth -= 1
            if depth == 0:
                return k
    return len(code)


def field_value(index, scope: str, name: str, field: str, codes: dict[str, str] | None = None,
                depth: int = 0) -> str | None:
    """The number literal that field *field* of the record constant *name* (looked up from class
    *scope*) has by its declaration (see the module), or None."""
    if depth > _MAX_DEPTH:
        return None
    codes = {} if codes is None else codes
    found = _record_constant(index, scope, name, codes)
    if found is None:
        return None
    cls, m = found
    code = own_text(index, cls, codes)
    if m.group("after") == "(":
        close = _skip_expr(code, m.end())
        if code[close:close + 1] != ")":
            close = _closing(code, m.end() - 1)
        inner = code[m.end():close]
        hit = None
        depth_at = 0
        for k, ch in enumerate(inner):  # the field set at the top level of the modification
            if ch in "([{":
                depth_at += 1
            elif ch in ")]}":
                depth_at -= 1
            elif depth_at == 0 and re.match(rf"(?<![\w.]){re.escape(field)}\s*=(?!=)", inner[k:]) \
                    and (k == 0 or not (inner[k - 1].isalnum() or inner[k - 1] in "_.")):
                hit = k
                break
        if hit is None:
            return None
        start = inner.index("=", hit) + 1
        value = inner[start:_skip_expr(inner, start)].strip()
        return value if _NUMBER.fullmatch(value) else None
    if m.group("after") == "=":
        bound = re.match(r"\s*([A-Za-z_][\w.]*)\s*;", code[m.end():])
        if bound is None or "." not in bound.group(1):
            return None
        owner_name, last = bound.group(1).rsplit(".", 1)
        owner = index.lookup(owner_name, cls)
        if owner is None or owner.rsplit(".", 1)[-1] != owner_name.rsplit(".", 1)[-1]:
            return None
        return field_value(index, owner, last, field, codes, depth + 1)
    return None


def _modified_anywhere(codes, name: str) -> bool:
    """Whether one of the class texts *codes* gives an element *name* a value in a modification or names it as an
    argument (``(name = ...`` or ``, name = ...``)."""
    pattern = re.compile(rf"[(,]\s*(?:(?:each|final)\s+)*{re.escape(name)}\s*=(?!=)")
    return any(pattern.search(code) for code in codes)


def _with_redeclared(index, used: list[str]) -> list[str]:
    """*used* and the classes a redeclaration nested in one of them reaches (a package's redeclared
    functions that a ``redeclare package`` brings in are not among the classes a model's names reach)."""
    out = dict.fromkeys(used)
    stack = list(used)
    while stack:
        for child in index.children.get(stack.pop(), {}).values():
            if child in out or not index.classes[child].redeclared:
                continue
            for cls in index.used_classes(child):
                if cls not in out:
                    out[cls] = None
                    stack.append(cls)
    return list(out)


_CONSTANT = re.compile(r"\bconstant\s+[A-Za-z_][\w.]*\s*(?:\[[^\];]*\]\s*)?\s([A-Za-z_]\w*)")


def replacements(index, model: str) -> dict[Path, dict[int, list[tuple[str, str]]]]:
    """file -> line -> [(reference, value)] for every field of a record constant that *model*'s classes
    read by simple name and whose value :func:`field_value` knows (see the module)."""
    used = _with_redeclared(index, index.used_classes(model))
    codes: dict[str, str] = {}
    for cls in used:
        own_text(index, cls, codes)
    constants = {m.group(1) for code in codes.values() for m in _CONSTANT.finditer(code)}
    out: dict[Path, dict[int, list[tuple[str, str]]]] = {}
    modified: dict[str, bool] = {}
    values: dict[tuple[str, str, str], str | None] = {}
    for cls in used:
        code = codes[cls]
        info = index.classes[cls]
        for m in _REF.finditer(code):
            name, field = m.group(1), m.group(2)
            if name not in constants or name in KEYWORDS or index.lookup(name, cls) is not None:
                continue  # no record constant of that name, or a class (package) name
            key = (cls, name, field)
            if key not in values:
                values[key] = field_value(index, cls, name, field, codes)
            value = values[key]
            if value is None:
                continue
            if name not in modified:
                modified[name] = _modified_anywhere([codes[c] for c in used], name)
            if modified[name]:
                continue
            line = index.location(info, m.start())[1]
            out.setdefault(info.file, {}).setdefault(line, []).append((m.group(0), value))
    return out


def patches(index, model: str) -> dict[Path, Callable[[bytes], bytes]]:
    """Per file, the edit that gives the front end such fields as their values (lines kept)."""
    found = replacements(index, model)
    out: dict[Path, Callable[[bytes], bytes]] = {}
    for file, by_line in found.items():
        def patch(body: bytes, by_line=by_line, file=file) -> bytes:
            lines = body.split(b"\n")
            done = 0
            for line, refs in by_line.items():
                if line > len(lines):
                    continue
                text = lines[line - 1].decode("utf-8", errors="surrogateescape")
                wanted = dict(refs)
                hits = [m for m in _REF.finditer(text)]
                if sum(1 for h in hits if h.group(0) in wanted) != len(refs):
                    continue  # the line is not as the index read it: left as written
                text = _REF.sub(lambda h: (f"({wanted[h.group(0)]})" if wanted[h.group(0)][0] in "+-"
                                           else wanted[h.group(0)]) if h.group(0) in wanted else h.group(0), text)
                lines[line - 1] = text.encode("utf-8", errors="surrogateescape")
                done += len(refs)
            if done:
                log.debug("%s: %d field(s) of record constants given to the front end as their values", file, done)
            return b"\n".join(lines)
        out[file] = patch
    return out
