"""Package constants modified twice along an extends chain, which rumoca 0.10.2 reads wrong.

In Modelica the outer modification wins (MLS 7.2.4): with

.. code-block:: modelica

    package A  constant Real cp = 1;  end A;
    package B  extends A(cp = 2);  end B;
    package C  extends B(cp = 4);  end C;

``C.cp`` is 4. rumoca 0.10.2 gives 2, the value of the inner clause, wherever ``C.cp`` is read (by
name, through a short class ``package M = C`` or a redeclared replaceable package), and a function
inherited into ``C`` that reads ``cp`` computes with 2 as well. Nothing warns. The same chain of
*models* (parameters) is flattened right; only packages lose the outer value
(``tests/test_compiler_package_constants.py`` measures both).

:func:`check_overridden_constants` refuses such a chain among the classes a model uses: a package
(or a short package class) whose modification gives an element a value that a modification in
an ``extends`` clause of one of its bases, at any depth, also gives a different value (the two
values compared as source text, blanks ignored; the same value twice changes nothing, e.g.
``Modelica.Media.Water.WaterIF97_ph`` repeating ``WaterIF97_base``'s ``smoothModel=false``).
"""
from __future__ import annotations

import re
from typing import TYPE_CHECKING

from ..errors import UnsupportedConstructError

if TYPE_CHECKING:  # (modifiers imports this module: no cycle at run time)
    from .library import ClassInfo
    from .modifiers import ModifierCheck

_EXTENDS = re.compile(r"\bextends\s+([\w.]+)\s*\(")
_SHORT_PACKAGE = re.compile(r"\bpackage\s+[A-Za-z_]\w*\s*=\s*([A-Za-z_][\w.]*)\s*\(")


def _value_text(text: str, offset: int) -> str | None:
    """The value of the modification element starting at *offset* (``[final] name[(...)] = value``),
    blanks removed; None if it gives none."""
    from .modifiers import _skip_expr

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
    from .modifiers import parse_modification

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


def check_overridden_constants(check: ModifierCheck, model: str, used: list[ClassInfo]) -> None:
    """Refuse a package of *used* whose modification overrides a value a base's extends clause
    gives the same element (see the module docstring)."""
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
                for _, _, inner_valued in _modifications(check, inner):
                    for element, (value, _) in valued.items():
                        if element in inner_valued and inner_valued[element][0] != value:
                            raise UnsupportedConstructError(
                                f"unsupported Modelica construct in {model}: package {c.simple} modifies "
                                f"{element} at {check._location(c, at)} where its base {inner.simple} "
                                f"modifies it too, at {check._location(inner, inner_valued[element][1])}: "
                                f"rumoca 0.10.2 keeps the inner value ({element} = "
                                f"{inner_valued[element][0]}) instead of the outer one ({element} = {value}) "
                                f"in a package"
                            )
