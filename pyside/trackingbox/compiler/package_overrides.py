"""Package constants modified twice along an extends chain, which rumoca 0.10.2 reads wrong; and
when another package's ``extends`` of a modified base is a use of it (:func:`one_branch_taken`).

In Modelica the outer modification wins (MLS 7.2.4): with

.. code-block:: modelica

    package A  constant Real cp = 1;  end A;
    package B  extends A(cp = 2);  end B;
    package C  extends B(cp = 4);  end C;

``C.cp`` is 4. rumoca 0.10.2 gives 2, the value of the inner clause, where ``C.cp`` is read by name
or through a short class (``package M = B(cp = 5)`` gives 2 as well), and a function inherited into
``C`` that reads ``cp`` computes with 2. Nothing warns. The same chain of
*models* (parameters) is flattened right; only packages lose the outer value
(``tests/test_compiler_package_constants.py`` measures both).

:func:`check_overridden_constants` refuses such a chain among the classes a model uses: a package
(or a short package class) whose modification gives an element a value that a modification in
an ``extends`` clause of one of its bases, at any depth, also gives a different value (the two
values compared as source text, blanks ignored; the same value twice changes nothing, e.g.
``Modelica.Media.Water.WaterIF97_ph`` repeating ``WaterIF97_base``'s ``smoothModel=false``).
"""
from __future__ import annotations

import logging
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from ..errors import UnsupportedConstructError
from .modification_parse import _skip_expr, parse_modification
from .source import read_text

if TYPE_CHECKING:  # (modifiers imports this module: no cycle at run time)
    from .library import ClassInfo
    from .modifiers import ModifierCheck

log = logging.getLogger(__name__)

_EXTENDS = re.compile(r"\bextends\s+([\w.]+)\s*\(")
_SHORT_PACKAGE = re.compile(r"\bpackage\s+[A-Za-z_]\w*\s*=\s*([A-Za-z_][\w.]*)\s*\(")


def _value_text(text: str, offset: int) -> str | None:
    """The value of the modification element starting at *offset* (``[final] name[(...)] = value``),
    blanks removed; None if it gives none."""
    depth = 0
    pos = offset
    while pos < len(text):
        ch = text[pos]
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            if depth == 0:
                return None
            depth -= 1
        elif depth == 0 and ch == ",":
            return None
        elif depth == 0 and ch == "=" and text[pos + 1:pos + 2] != "=":
            end = _skip_expr(text, pos + 1)
            return re.sub(r"\s+", "", text[pos + 1:end])
        pos += 1
    return None


def _valued(text: str, paren: int) -> dict[str, tuple[str, int]]:
    """The elements the modification ``( ... )`` at *paren* gives a value: name -> (value, offset)."""
    mods, _ = parse_modification(text, paren)
    out: dict[str, tuple[str, int]] = {}
    for m in mods:
        if m.has_value:
            value = _value_text(text, m.offset)
            if value is not None:
                out[m.name] = (value, m.offset)
    return out


def _modifications(check: ModifierCheck, c: ClassInfo) -> list[tuple[str, int, dict[str, tuple[str, int]]]]:
    """(base name, offset of the clause, valued elements) of each extends clause of package *c*, and
    of its short-class definition's modification."""
    text = check.body(c)
    found = []
    pattern = _SHORT_PACKAGE if c.short else _EXTENDS
    for m in pattern.finditer(text):
        valued = _valued(text, m.end() - 1)
        if valued:
            found.append((m.group(1), m.start(), valued))
    return found


def _base_named(check: ModifierCheck, c: ClassInfo, name: str) -> str | None:
    simple = name.rsplit(".", 1)[-1]
    return next((b for b in check.index.bases(c.name) if b.rsplit(".", 1)[-1] == simple), None)


class _Override(NamedTuple):
    package: ClassInfo
    at: int  # offset of its extends clause (or short class) in its text
    element: str
    value: str
    inner: ClassInfo  # the base whose own clause modifies the element too
    inner_at: int  # offset of that modification's element in its text
    inner_value: str
    inner_base: str  # the class that clause extends, as written
    inner_clause: int  # offset of that clause


def _overrides(check: ModifierCheck, used: list[ClassInfo]) -> Iterator[_Override]:
    """Each place where a package of *used* modifies an element that a base of it, at any depth,
    modifies with another value in an ``extends`` clause of its own."""
    classes = check.index.classes
    for c in used:
        if c.kind != "package":
            continue
        for base_name, at, valued in _modifications(check, c):
            base = _base_named(check, c, base_name)
            seen: set[str] = set()
            todo = [base] if base else []
            while todo:
                name = todo.pop()
                if name in seen or name not in classes:
                    continue
                seen.add(name)
                inner = classes[name]
                todo.extend(check.index.bases(name))
                if inner.kind != "package":
                    continue
                for inner_base, inner_clause, inner_valued in _modifications(check, inner):
                    for element, (value, _) in valued.items():
                        if element in inner_valued and inner_valued[element][0] != value:
                            yield _Override(c, at, element, value, inner, inner_valued[element][1],
                                            inner_valued[element][0], inner_base, inner_clause)


def _declared_value(check: ModifierCheck, start: str | None, element: str) -> str | None:
    """The value (blanks removed) that the declaration ``constant T element = value`` gives *element*
    in package *start* or the bases it inherits it from, where no ``extends`` clause along the way
    modifies it; None where it is declared otherwise or modified on the way."""
    classes = check.index.classes
    declared = re.compile(rf"\bconstant\s+[A-Za-z_][\w.]*\s*(?:\[[^\]]*\]\s*)?{re.escape(element)}\s*=")
    seen: set[str] = set()
    todo = [start] if start else []
    while todo:
        name = todo.pop(0)
        if name in seen or name not in classes:
            continue
        seen.add(name)
        text = check.body(classes[name])
        m = declared.search(text)
        if m:
            end = text.find(";", m.end())  # (a description string is blanked)
            return re.sub(r"\s+", "", text[m.end():end]) if end >= 0 else None
        if any(element in valued for _, _, valued in _modifications(check, classes[name])):
            return None
        todo.extend(check.index.bases(name))
    return None


def _repeats_declaration(check: ModifierCheck, inner: ClassInfo, base_name: str, element: str, value: str) -> bool:
    """Whether *inner*'s modification ``element = value`` in its clause extending *base_name* gives the
    value *element* has there anyway (``WaterIF97_base``'s ``smoothModel=false`` over
    ``PartialTwoPhaseMedium``'s ``constant Boolean smoothModel=false``): such a modification changes
    nothing in Modelica, and without it rumoca reads the outer one."""
    return _declared_value(check, _base_named(check, inner, base_name), element) == value


def check_overridden_constants(check: ModifierCheck, model: str, used: list[ClassInfo]) -> None:
    """Refuse a package of *used* whose modification overrides a value a base's extends clause
    gives the same element (see the module docstring), unless that inner modification only repeats
    the value the element's declaration gives (:func:`patches` then blanks it for rumoca)."""
    for c, at, element, value, inner, inner_at, inner_value, inner_base, _ in _overrides(check, used):
        if _repeats_declaration(check, inner, inner_base, element, inner_value):
            continue
        raise UnsupportedConstructError(
            f"unsupported Modelica construct in {model}: package {c.simple} modifies "
            f"{element} at {check._location(c, at)} where its base {inner.simple} "
            f"modifies it too, at {check._location(inner, inner_at)}: "
            f"rumoca 0.10.2 keeps the inner value ({element} = "
            f"{inner_value}) instead of the outer one ({element} = {value}) "
            f"in a package"
        )


def _clause_edits(text: str, paren: int, drop: set[int]) -> list[tuple[int, int]]:
    """The spans of *text* to blank so that the modification ``( ... )`` at *paren* loses its
    elements starting at the offsets *drop* and stays well formed (a comma is kept after an element
    that stays and has another after it)."""
    ends = []  # the position of the comma or ')' after each element
    pos = paren + 1
    while True:
        pos = _skip_expr(text, pos)
        ends.append(pos)
        if pos >= len(text) or text[pos] == ")":
            break
        pos += 1
    starts = [paren + 1] + [e + 1 for e in ends[:-1]]
    gone = [any(a <= d < b for d in drop) for a, b in zip(starts, ends)]
    spans = []
    for i, (a, b) in enumerate(zip(starts, ends)):
        if gone[i]:
            spans.append((a, b))
        if i < len(ends) - 1 and (gone[i] or all(gone[i + 1:])):
            spans.append((b, b + 1))  # the comma after it
    return spans


def patches(check: ModifierCheck, model: str) -> dict[Path, Callable[[bytes], bytes]]:
    """For the files of the packages *model* uses: the edit that blanks each modification that
    :func:`check_overridden_constants` lets pass because it repeats its element's declared value
    under an outer one (lines and byte offsets kept), so that rumoca reads the outer value."""
    index = check.index
    drops: dict[tuple[str, int], set[int]] = {}  # (package, offset of its clause's '(') -> element offsets
    for o in _overrides(check, check.used_classes(model)):
        if _repeats_declaration(check, o.inner, o.inner_base, o.element, o.inner_value):
            paren = check.body(o.inner).index("(", o.inner_clause)
            drops.setdefault((o.inner.name, paren), set()).add(o.inner_at)
    edits: dict[Path, list[tuple[int, bytes]]] = {}
    for (name, paren), offsets in drops.items():
        info = index.classes[name]
        full = read_text(info.file)
        for a, b in _clause_edits(check.body(info), paren, offsets):
            lo = len(full[:info.start + a].encode())
            edits.setdefault(info.file, []).append((lo, full[info.start + a:info.start + b].encode()))
            log.debug("%s: %s read without the modification %r, which repeats the declared value",
                      info.file, name, full[info.start + a:info.start + b])

    def patch_for(file: Path, spans: list[tuple[int, bytes]]) -> Callable[[bytes], bytes]:
        def patch(body: bytes) -> bytes:
            for lo, old in spans:
                if body[lo:lo + len(old)] != old:
                    raise UnsupportedConstructError(
                        f"unsupported Modelica construct in {model}: a package constant modified twice "
                        f"along an extends chain at {file}, where the text the front end reads differs "
                        f"from the library's")
                body = body[:lo] + re.sub(rb"[^\n]", b" ", old) + body[lo + len(old):]
            return body
        return patch

    return {f: patch_for(f, spans) for f, spans in edits.items()}


# --- another package's extends of a modified base ----------------------------------------------
#
# rumoca 0.10.2 mixes the constants of two packages that extend the same base with different
# modifications where both are *taken as packages* by the model: a component's redeclared or default
# replaceable package (``tests/test_compiler_package_constants.py``: two components with media of
# the base's two branches compute one's functions with the other's constants; a default that is
# redeclared away lends the package that replaces it its modifications). A sibling that is never
# taken so changes nothing: two branches read by name (``PSM.f(...)``, ``PT.f(...)``), or a
# constant read from a package the model does not take as its medium, come out right (measured in
# the same test file). So another package's ``extends B`` is no use of ``B`` when every package the
# model's classes take (``package X = Y``, ``redeclare package X = Y``, ``constrainedby Y``) that
# extends ``B`` is one package and its own bases (Modelica.Fluid.Examples.PumpingSystem: the medium
# ``WaterIF97_pT`` and the constraining ``PartialTwoPhaseMedium``; ``ConstantPropertyLiquidWater``,
# whose ``PartialSimpleMedium`` modifies ``PartialPureSubstance``, only imported by
# ``Modelica.Media.Water``).

_TAKEN = re.compile(r"\bpackage\s+\w+\s*=\s*([A-Za-z_][\w.]*)|\bconstrainedby\s+([A-Za-z_][\w.]*)")


def only_in_extends(text: str, name: str) -> bool:
    """Whether *name* stands in *text* (a class's comment-free own text) only as the class an
    ``extends`` clause names."""
    esc = re.escape(name)
    every = len(re.findall(rf"(?<![\w.]){esc}(?![\w])", text))
    extended = len(re.findall(rf"\bextends\s+{esc}(?![\w.])", text))
    return every > 0 and every == extended


def only_in_imports(text: str, name: str) -> bool:
    """Whether *name* stands in *text* (a class's comment-free own text) only as what an ``import``
    clause imports (``import A.B;``, ``import C = A.B;``, ``import A.B.*``): an import alone uses
    nothing (MLS 13.2.1); a name that uses it is a name of its own in the class's text."""
    esc = re.escape(name)
    every = len(re.findall(rf"(?<![\w.]){esc}(?![\w])", text))
    imported = len(re.findall(rf"\bimport\s+(?:[A-Za-z_]\w*\s*=\s*)?\.?{esc}(?![\w])", text))
    return every > 0 and every == imported


def _final(check: ModifierCheck, name: str) -> str | None:
    """The class a short class chain ``package A = B`` ends at (None where it cannot be followed)."""
    classes = check.index.classes
    seen: set[str] = set()
    while name in classes and classes[name].short:
        if name in seen:
            return None
        seen.add(name)
        bases = check.index.bases(name)
        if not bases:
            return None
        name = bases[0]
    return name if name in classes else None


def _ancestors(check: ModifierCheck, name: str) -> set[str]:
    out: set[str] = set()
    todo = [name]
    while todo:
        n = todo.pop()
        if n not in out:
            out.add(n)
            todo.extend(check.index.bases(n))
    return out


def one_branch_taken(check: ModifierCheck, used: list[ClassInfo], base: str) -> bool:
    """Whether the packages the classes of *used* take (see above) that extend *base* are one package
    and its own bases; False where a taken package cannot be resolved."""
    leaves = taken_branches(check, used, base)
    return leaves is not None and len(leaves) <= 1


def _library_alias(check: ModifierCheck, c: ClassInfo) -> bool:
    """Whether *c* is a short package class of a package, neither replaceable nor a redeclaration
    (``package StandardWater = WaterIF97_ph`` in ``Modelica.Media.Water``): a name for the package it
    ends at, which a model reaches only by name (``Modelica.Media.Water.StandardWater.density(state)``
    in ``Modelica.Media.CompressibleLiquids.Common.LinearWater_pT``'s constants), not a package the
    model takes as a medium; through it, as through the full name, rumoca 0.10.2 reads that package's
    own functions and constants (``DirectOther`` in ``tests/test_compiler_package_constants.py``). Its
    own text, ``package StandardWater = WaterIF97_ph``, is no take (a model's short package class or
    a replaceable one is)."""
    if not c.short or c.kind != "package" or c.redeclared:
        return False
    parent = check.index.classes.get(c.name.rsplit(".", 1)[0]) if "." in c.name else None
    if parent is None or parent.kind != "package":
        return False
    return re.match(r"\s*(?:\w+\s+)*?(?:replaceable|redeclare)\b", check.body(c)) is None


def taken_branches(check: ModifierCheck, used: list[ClassInfo], base: str) -> dict[str, tuple[ClassInfo, int]] | None:
    """The packages extending *base* that the classes of *used* take (see above), none a base of
    another, each with the class and offset in its text of a place taking it (a short package
    class ending at it, or the clause naming it); None where a taken package cannot be resolved."""
    taken: dict[str, tuple[ClassInfo, int]] = {}
    texts = []
    for c in used:
        if not _library_alias(check, c):
            texts.append((c, c))  # (a redeclaration in a modification)
        for child in check.index.children.get(c.name, {}).values():
            k = check.index.classes.get(child)
            if k is None or not k.short or k.kind != "package":
                continue
            if not _library_alias(check, k):
                texts.append((c, k))  # a package a model declares, or a replaceable one anywhere
    for c, where in texts:
        for m in _TAKEN.finditer(check.body(where)):
            target = check.index.lookup(m.group(1) or m.group(2), c.name)
            final = _final(check, target) if target else None
            if final is None:
                return None
            if base in _ancestors(check, final) - {final}:
                taken.setdefault(final, (where, m.start()))
    return {t: at for t, at in taken.items() if not any(t != o and t in _ancestors(check, o) for o in taken)}


# --- branches whose modified constants no class of theirs reads ---------------------------------
#
# What rumoca 0.10.2 mixes between two taken branches is what the classes of the base compute from
# the constants the branches modify: a function the branches inherit from a base that modifies a
# constant of its own base computes one branch's call with the other's value (``TwoI`` in
# ``tests/test_compiler_package_constants.py``), while a constant read from outside through the
# taken package (``WallFriction.use_mu`` in a flow model) comes out right (measured there). So where
# no class of the family (the base, its bases, the used packages extending it, and every class nested
# in them) reads an element that an extends clause of the family gives a value, besides its own
# declaration, the branches compute alike in rumoca and in Modelica (Modelica.Fluid's wall frictions:
# ``LaminarAndQuadraticTurbulent`` and ``Detailed`` set ``use_mu``, ``use_roughness`` ... of
# ``PartialWallFriction``, read only by the flow models, from outside).

def _nested(check: ModifierCheck, name: str) -> Iterator[str]:
    yield name
    for child in check.index.children.get(name, {}).values():
        yield from _nested(check, child)


def family_reads_modified(check: ModifierCheck, used: list[ClassInfo], base: str) -> bool:
    """Whether a class of *base*'s family among *used* reads an element that an extends clause of
    the family modifies (see above); True where a class cannot be read."""
    classes = check.index.classes
    family = set(_ancestors(check, base))
    family |= {c.name for c in used if c.kind == "package" and base in _ancestors(check, c.name)}
    names: set[str] = set()
    for name in family:
        if name in classes and classes[name].kind == "package":
            for _, _, valued in _modifications(check, classes[name]):
                names |= set(valued)
    if not names:
        return False
    read = re.compile(r"(?<![\w.])(?:" + "|".join(map(re.escape, sorted(names))) + r")\b")
    declared = re.compile(r"\b(?:constant|parameter)\s+[A-Za-z_][\w.]*\s*(?:\[[^\];]*\]\s*)?(?:"
                          + "|".join(map(re.escape, sorted(names))) + r")\b")
    for top in family:
        for name in _nested(check, top):
            info = classes.get(name)
            if info is None:
                return True
            text = check.body(info)
            for m in _EXTENDS.finditer(text):  # the family's own modifications of the elements
                end = m.end()
                while end < len(text) and text[end] != ")":
                    end = _skip_expr(text, end + (text[end] == ","))
                text = text[:m.end()] + " " * (end - m.end()) + text[end:]
            text = declared.sub(lambda d: " " * len(d.group(0)), text)
            if read.search(text):
                return True
    return False
