"""Tracked parameters wherever a modeller puts them (issue 30, item 5).

Two places the conditional-input pattern of :mod:`.source` cannot be switched on directly:

* a **top-level parameter** of the twin passed down to components by modifiers
  (``parameter Real R1; ThermalResistor thermalResistor1(R = R1);``): the box drives every
  component parameter bound to it (:func:`.parameter_uses.receivers`);
* a parameter of a component whose class lives in a **read-only library** (the MSL, or any
  library given with ``[source] libraries``/``--library``/``MODELICAPATH``): the generated package
  gets its own *variant* of that class, the library class's text with its names written in full
  and the pattern added for the parameter (:func:`class_variant`), and its own *variant of the
  twin*, the twin's text with the component's class switched to it (:func:`twin_variant`). The
  library is never edited; the review is a diff of generated files.

A parameter that cannot follow an input is refused, naming why (:func:`.parameter_uses.structural_reason`):
``Evaluate = true``, not a Real, used in another parameter's binding, a start value, an array size
or a modifier, or (a top-level one) in the twin's own equations.
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from ..compiler.library import LibraryIndex, index_for
from ..compiler.source import read_text, resolve_source, strip_comments
from ..errors import SpecError

__all__ = ["Variant", "TwinVariant", "library_index",
           "component_class", "declaring_class", "class_variant", "twin_variant", "is_library_class"]

#: Modelica words that are never class names (not looked up when names are written in full)
_KEYWORDS = frozenset("""algorithm and annotation assert block break class connect connector constant
constrainedby der discrete each else elseif elsewhen encapsulated end enumeration equation expandable
extends external false final flow for function if import impure in initial inner input loop model not
operator or outer output package parameter partial protected public pure record redeclare replaceable
return stream then true type when while within time""".split())
_NAME = re.compile(r"(?<![\w.])([A-Za-z_]\w*)((?:\s*\.\s*[A-Za-z_]\w*)*)")
_ANNOTATION = re.compile(r"(?<![\w.])annotation\s*\(")


@dataclass(frozen=True)
class Variant:
    """A generated variant of a library class: its text with the pattern for *leaves*."""

    library_class: str
    name: str
    leaves: tuple[str, ...]
    text: str


@dataclass(frozen=True)
class TwinVariant:
    """The twin's text with some components' classes switched to variants."""

    name: str
    twin: str
    switched: Mapping[str, str]
    text: str


# --------------------------------------------------------------------------- the classes

def library_index(path: Path, libraries: tuple[Path, ...]) -> LibraryIndex:
    """The compiler's index of the twin's source and its libraries (name lookup in a class's scope)."""
    return index_for(resolve_source(path), libraries)


#: top-level packages that are read-only libraries even when the twin lives in them (its examples)
READ_ONLY_PACKAGES = frozenset({"Modelica", "ModelicaServices", "Complex"})


def is_library_class(index: LibraryIndex, cls: str, own_top: Path, read_only: tuple[Path, ...] = ()) -> bool:
    """True if class *cls* is a read-only library's, not the twin's own package's to change.

    A class outside the twin's own package *own_top* is a library's. So is every class of the
    twin's own package when that package is itself read-only: the Modelica Standard Library
    (:data:`READ_ONLY_PACKAGES`, a twin that is one of its examples) or one of *read_only*
    (the ``[source] libraries`` and ``--library`` paths).
    """
    info = index.classes.get(cls)
    if info is None:
        return False
    top = own_top.resolve()
    if top.name.removesuffix(".mo") in READ_ONLY_PACKAGES or top in {Path(p).resolve() for p in read_only}:
        return True
    file = info.file.resolve()
    return not (file == top or top in file.parents)


def _declared_in(code: str, ident: str, *, parameter: bool) -> tuple[str, int] | None:
    """(type name, offset) of the declaration of *ident* in a class's own code, or None."""
    for stmt in re.finditer(r"[^;]+;", code):
        text = stmt.group(0)
        skip = 0
        head_match = re.match(r"\s*(?:(?:partial|encapsulated|final|replaceable|expandable|pure|impure)\s+)*"
                              r"(?:model|block|class|connector|record|package|function|type)\s+[A-Za-z_]\w*", text)
        if head_match:  # the class's first element follows its head (and description) in one statement
            skip = head_match.end()
        if parameter:
            kw = re.search(r"(?<![\w.])parameter\b", text[skip:])
            if kw is None:
                continue
            skip += kw.end()
        head = re.split(r"[(=]", text[skip:], maxsplit=1)[0]
        tokens = [(m.group(0), skip + m.start()) for m in re.finditer(r"[A-Za-z_][\w.]*", head)]
        tokens = [(t, o) for t, o in tokens if t not in _KEYWORDS and t not in ("each",)]
        if len(tokens) >= 2 and tokens[1][0] == ident and re.fullmatch(r"[A-Za-z_][\w.]*", tokens[0][0]):
            return tokens[0][0], stmt.start() + tokens[1][1]
    return None


def _own_code(index: LibraryIndex, cls: str) -> str:
    info = index.classes[cls]
    return index.own_code(info, annotations=False)


def component_class(index: LibraryIndex, cls: str, component: str) -> tuple[str, str] | None:
    """``(class of the component, class that declares it)`` for a component of *cls* (or its bases)."""
    seen: set[str] = set()
    todo = [cls]
    while todo:
        c = todo.pop(0)
        if c in seen or c not in index.classes:
            continue
        seen.add(c)
        found = _declared_in(_own_code(index, c), component, parameter=False)
        if found is not None:
            target = index.lookup(found[0], c)
            if target is not None:
                return target, c
        todo.extend(index.bases(c))
    return None


def declaring_class(index: LibraryIndex, cls: str, leaf: str) -> str | None:
    """The class (*cls* or one of its bases) whose own text declares the parameter *leaf*."""
    seen: set[str] = set()
    todo = [cls]
    while todo:
        c = todo.pop(0)
        if c in seen or c not in index.classes:
            continue
        seen.add(c)
        if _declared_in(_own_code(index, c), leaf, parameter=True) is not None:
            return c
        todo.extend(index.bases(c))
    return None


def _paren_end(code: str, pos: int) -> int:
    depth = 0
    for m in re.compile(r"[()]").finditer(code, pos):
        depth += 1 if m.group(0) == "(" else -1
        if depth == 0:
            return m.end()
    return len(code)


def _class_text(index: LibraryIndex, cls: str, new_name: str) -> str:
    """The text of class *cls*, names written in full, annotations left out, renamed *new_name*."""
    info = index.classes[cls]
    original = read_text(info.file)[info.start:info.end]
    code = strip_comments(original)
    cuts: list[tuple[int, int, str]] = []
    for m in _ANNOTATION.finditer(code):
        end = _paren_end(code, m.end() - 1)
        after = re.match(r"\s*;", code[end:])
        before = code[:m.start()].rstrip()
        start = m.start()
        if after and (before.endswith(";") or re.search(r"\b(equation|algorithm|public|protected)$", before)):
            end += after.end()  # a class annotation: the whole statement goes
        else:
            start = len(original[:m.start()].rstrip())  # an element's annotation: its text (description) stays
        cuts.append((start, end, ""))
    for m in _NAME.finditer(code):
        first = m.group(1)
        if first in _KEYWORDS or any(a <= m.start() < b for a, b, _ in cuts):
            continue
        if code[m.end():m.end() + 1] == "(" and first in ("der", "connect", "noEvent", "smooth", "pre",
                                                           "initial", "sample", "edge", "change"):
            continue
        target = index.lookup(first, cls)
        if target is None or target == cls:
            continue
        cuts.append((m.start(), m.start() + len(first), target))
    out, pos = [], 0
    for a, b, text in sorted(cuts):
        if a < pos:
            continue
        out.append(original[pos:a])
        out.append(text)
        pos = b
    out.append(original[pos:])
    text = "".join(out)
    simple = info.simple
    head = re.search(rf"\b{re.escape(simple)}\b", text)
    tail = list(re.finditer(rf"\bend\s+{re.escape(simple)}\s*;", text))
    if head is None or not tail:
        raise SpecError(f"cannot read the class {cls} in {info.file}: its name is not where the index has it")
    last = tail[-1]
    text = (text[:head.start()] + new_name + text[head.end():last.start()] + f"end {new_name};")
    # blank lines left where annotations were
    return re.sub(r"\n[ \t]*(?=\n[ \t]*\n)", "", text).strip() + "\n"


def class_variant(index: LibraryIndex, cls: str, name: str, leaves: tuple[str, ...], connector: str,
                  package: str) -> Variant:
    """The variant *name* of the library class *cls* with the parameters *leaves* switchable to inputs."""
    from .source import Declaration, _blank_comments_strings, _patch_class_text  # the pattern, written once

    text = _class_text(index, cls, name)
    for leaf in leaves:
        code = _blank_comments_strings(text)
        found = _declared_in(code, leaf, parameter=True)
        if found is None:
            raise SpecError(f"the parameter {leaf!r} is not declared in the text of {cls} itself (it is inherited "
                            f"from a base class): gen-trackingbox makes variants of the declaring class only")
        offset = found[1]
        start = code.rfind("parameter", 0, offset)
        end = code.index(";", offset) + 1
        decl = Declaration(file=Path(f"{name}.mo"), line=text.count("\n", 0, start) + 1, class_name=name,
                           class_kind="model", start=start, end=end)
        try:
            text = _patch_class_text(text, decl, leaf, connector)
        except SpecError as exc:
            raise SpecError(f"{cls}.{leaf} cannot follow an input: {exc}") from None
    header = (f"within {package};\n// Generated by trackingbox from {cls} (the library is not edited): the same "
              f"class with {', '.join(leaves)} taken from an input when use_<name>_in = true.\n")
    return Variant(library_class=cls, name=name, leaves=leaves, text=header + text)


def twin_variant(index: LibraryIndex, twin: str, name: str, switched: Mapping[str, str], package: str) -> TwinVariant:
    """The twin's text as *name*, with each component of *switched* (component -> variant class) switched."""
    text = _class_text(index, twin, name)
    for component, target in sorted(switched.items()):
        code = strip_comments(text)
        found = _declared_in(code, component, parameter=False)
        if found is None:
            raise SpecError(f"component {component!r} is not declared in the twin {twin} itself (inherited from a "
                            f"base class): gen-trackingbox switches the class of the twin's own components only")
        type_name, at = found
        start = code.rfind(type_name, 0, at)
        text = text[:start] + target + text[start + len(type_name):]
    header = (f"within {package};\n// Generated by trackingbox from {twin}: the same model with "
              f"{', '.join(sorted(switched))} of the classes generated beside it.\n")
    return TwinVariant(name=name, twin=twin, switched=dict(switched), text=header + text)
