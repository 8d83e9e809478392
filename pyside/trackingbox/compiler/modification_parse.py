"""Modifications read from comment-free Modelica source text: ``( name(sub...) = value, ... )``
(shared by :mod:`.modifiers` and :mod:`.package_overrides`)."""
from __future__ import annotations

import re
from dataclasses import dataclass, field

_IDENT = re.compile(r"[A-Za-z_]\w*")
_KEYWORDS = {"each", "final", "redeclare", "replaceable"}


@dataclass
class Mod:
    """One element of a modification: ``name(sub...) = value``."""

    name: str
    subs: list[Mod] = field(default_factory=list)
    has_value: bool = False
    offset: int = 0


def _skip_expr(text: str, pos: int) -> int:
    """Position of the ``,`` or ``)`` that ends the expression starting at *pos*."""
    depth = 0
    while pos < len(text):
        ch = text[pos]
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            if depth == 0:
                return pos
            depth -= 1
        elif ch == "," and depth == 0:
            return pos
        pos += 1
    return pos


def parse_modification(text: str, pos: int) -> tuple[list[Mod], int]:
    """Parse ``( ... )`` at *pos* (comments and strings already blanked); return the elements and the end."""
    assert text[pos] == "("
    pos += 1
    mods: list[Mod] = []
    while pos < len(text):
        while pos < len(text) and text[pos] in " \t\r\n,":
            pos += 1
        if pos >= len(text):
            break
        if text[pos] == ")":
            return mods, pos + 1
        start = pos
        m = _IDENT.match(text, pos)
        while m and m.group(0) in _KEYWORDS:
            if m.group(0) in ("redeclare", "replaceable"):
                m = None
                break
            pos = m.end()
            while pos < len(text) and text[pos] in " \t\r\n":
                pos += 1
            m = _IDENT.match(text, pos)
        if m is None:  # a redeclaration or something we do not read: skip it
            pos = _skip_expr(text, pos)
            continue
        names = [m.group(0)]
        pos = m.end()
        while pos < len(text) and text[pos] == ".":  # a.b = 1 is a(b = 1)
            m2 = _IDENT.match(text, pos + 1)
            if not m2:
                break
            names.append(m2.group(0))
            pos = m2.end()
        while pos < len(text) and text[pos] in " \t\r\n":
            pos += 1
        if pos < len(text) and text[pos] == "[":  # subscripted element: skip the subscripts
            pos = _skip_expr(text, pos)
        mod = Mod(names[-1], offset=start)
        if pos < len(text) and text[pos] == "(":
            mod.subs, pos = parse_modification(text, pos)
        while pos < len(text) and text[pos] in " \t\r\n":
            pos += 1
        if pos < len(text) and text[pos] in "=:":
            mod.has_value = True
            pos = _skip_expr(text, pos + 1)
        else:
            pos = _skip_expr(text, pos)
        for outer in reversed(names[:-1]):
            mod = Mod(outer, subs=[mod], offset=start)
        mods.append(mod)
    return mods, pos
