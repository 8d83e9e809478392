"""Class redeclarations whose modification names other elements, read by rumoca as a modification
of the component that the redeclared class types.

rumoca 0.10.2 drops the modification of ``redeclare model FlowModel = NominalTurbulentPipeFlow(
m_flow_turbulent = eps*1, ...)`` (:mod:`.modifiers`); :mod:`.redeclare_short` keeps a literal one
through a short class, but rumoca evaluates a name in a short class's modification at translation
(the parameter ``eps`` then disappears from the FMU and no longer reaches the pipe). Where the
redeclaration stands in the modification of a component declaration,

.. code-block:: modelica

    StaticPipe pipe1(redeclare model FlowModel = NominalTurbulentPipeFlow(m_flow_turbulent = eps*1));

and the class ``StaticPipe`` (with its bases) uses ``FlowModel`` only as the replaceable class's own
declaration and as the type of scalar components (``FlowModel flowModel(final n = 2, ...)``), the
modification means, in Modelica, that each such component gets those values unless its declaration
or a modification between them says otherwise (MLS 7.2.4: the outer modification wins, the class's
own one is the innermost); its expressions are looked up where the redeclaration stands (MLS 7.3),
the scope of ``pipe1``'s own modification. So, where no declaration of the component, no extends
clause of the class's chain and no other element of ``pipe1``'s modification modifies the component,
and no constraining clause of the replaceable declaration modifies anything, it is the same as

.. code-block:: modelica

    StaticPipe pipe1(redeclare model FlowModel = NominalTurbulentPipeFlow, flowModel(m_flow_turbulent = eps*1));

which rumoca keeps (``tests/test_compiler_redeclare_components.py``: the parameter stays tunable and
reaches the component). :func:`patches` writes it so (lines kept); every other case stays refused by
:mod:`.modifiers`, naming the redeclaration.
"""
from __future__ import annotations

import logging
import re
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from ..errors import UnsupportedConstructError
from .modification_parse import _skip_expr, parse_modification
from .redeclare_short import REDECLARATION, short_class_handles
from .source_scan import _code_mask, _matching_paren

log = logging.getLogger(__name__)

_KINDS = r"(?:model|block|class|connector|record)"
_REDECL = re.compile(rf"\bredeclare\s+(?:(?:replaceable|final|each)\s+)*({_KINDS})\s+(\w+)\s*=\s*([\w.]+)\s*\(")
_PREFIX = r"(?:(?:parameter|constant|discrete|input|output|flow|stream|inner|outer|final|replaceable)\s+)*"
_COMPONENT = re.compile(rf"(?:^|[;]|\bpublic|\bprotected)\s*{_PREFIX}(?P<type>[A-Za-z_][\w.]*)\s+(?P<comp>[A-Za-z_]\w*)\s*$")
_NOT_TYPES = {"extends", "import", "end", "within", "redeclare", "annotation", "equation", "algorithm"}
_HEADER = re.compile(r"\s*(?:(?:encapsulated|partial|final|expandable|pure|impure|operator)\s+)*"
                     r"(?:model|block|class|record|connector|package|function|type)\s+[A-Za-z_]\w*")
_SIMPLE = re.compile(r"\s*(?:(?:final|each)\s+)*[A-Za-z_]\w*\s*=(?!=)")


class Plan(NamedTuple):
    """What :func:`plan` found for one redeclaration: the redeclared name, the components of that
    class in the component's class, and the modification's text (without its parentheses)."""

    name: str
    components: tuple[str, ...]
    modification: str


def _nested(index, cls: str) -> list[str]:
    out = [cls]
    for child in index.children.get(cls, {}).values():
        out.extend(_nested(index, child))
    return out


def _enclosing_paren(text: str, at: int) -> int | None:
    """The offset of the innermost parenthesis open at *at*, where it is the only one open."""
    depth, found = 0, None
    for k, ch in enumerate(text[:at]):
        if ch in "([{":
            depth += 1
            if depth == 1:
                found = k
        elif ch in ")]}":
            depth -= 1
    return found if depth == 1 and text[found] == "(" else None


def _uses(index, chain: list[str], name: str) -> tuple[bool, list[tuple[str, set[str]]]] | None:
    """Whether a replaceable declaration of *name* stands in *chain*, and (component, names its
    declaration modifies) of each scalar component of that class; None where *name* stands anywhere
    else, in a nested class too, or the replaceable declaration carries a modification."""
    word = re.compile(rf"(?<![\w.]){re.escape(name)}(?!\w)")
    esc = re.escape(name)
    declared = re.compile(rf"\s*(?:(?:public|protected)\s+)?replaceable\s+{_KINDS}\s+{esc}\s*=\s*[\w.]+"
                          rf"(?:\s+constrainedby\s+[\w.]+)?\s*(?:annotation\s*\(\s*\)\s*)?;?\s*$")
    component = re.compile(rf"\s*(?:(?:public|protected)\s+)?{_PREFIX}{esc}\s+([A-Za-z_]\w*)\s*(\(|;|if\b)")
    replaceable, comps = False, []
    for top in chain:
        own = index.children.get(top, {}).get(name)
        if own is not None:  # the replaceable class itself (a class of its own in the index)
            if not declared.match(index.own_code(index.classes[own], annotations=False)):
                return None
            replaceable = True
        for cls in _nested(index, top):
            if cls == own:
                continue
            text = index.own_code(index.classes[cls], annotations=False)
            for hit in word.finditer(text):
                head = text.rfind(";", 0, hit.start()) + 1
                if head == 0:  # the first element: after the class's header
                    header = _HEADER.match(text)
                    head = header.end() if header else 0
                c = component.match(text, head)
                if cls == top and c and c.start(1) > hit.start():
                    given = {m.name for m in parse_modification(text, c.end(2) - 1)[0]} if c.group(2) == "(" else set()
                    comps.append((c.group(1), given))
                    continue
                return None
    return replaceable, comps


def _modified_in_chain(index, chain: list[str], comps: set[str]) -> set[str]:
    """The names that extends clauses or short-class modifications of *chain* give *comps*."""
    out: set[str] = set()
    for cls in chain:
        text = index.own_code(index.classes[cls], annotations=False)
        for m in re.finditer(r"(?:\bextends|=)\s*[A-Za-z_][\w.]*\s*\(", text):
            for mod in parse_modification(text, m.end() - 1)[0]:
                if mod.name in comps:
                    out |= {s.name for s in mod.subs} | ({"="} if mod.has_value else set())
    return out


def plan(index, cls: str, text: str, at: int) -> Plan | None:
    """The rewrite of the class redeclaration at offset *at* of *text* (the comment-free own text of
    class *cls*, annotations blanked) as a modification of components (see the module's docstring);
    None where it does not mean the same."""
    m = _REDECL.match(text, at)
    if m is None or short_class_handles(text, at):
        return None
    mods, _ = parse_modification(text, m.end() - 1)
    pos, elements = m.end(), []
    while True:
        end = _skip_expr(text, pos)
        elements.append(text[pos:end])
        if end >= len(text) or text[end] == ")":
            break
        pos = end + 1
    if end >= len(text):
        return None
    close = end
    if not mods or len(mods) != len(elements) or any(
            not x.has_value or x.subs for x in mods) or not all(_SIMPLE.match(e) for e in elements):
        return None  # only elements given values (k = expression): nested ones are read elsewhere
    paren = _enclosing_paren(text, at)
    if paren is None:
        return None
    decl = _COMPONENT.search(text, max(0, paren - 300), paren)
    if decl is None or decl.group("type") in _NOT_TYPES:
        return None
    owner = index.lookup(decl.group("type"), cls)
    if owner is None:
        return None
    chain = index.ancestors(owner)
    found = _uses(index, chain, m.group(2))
    if found is None or not found[0] or not found[1]:
        return None
    comps = found[1]
    names = {x.name for x in mods}
    if any(given & names for _, given in comps):
        return None  # a declaration's own modification of the same element would win
    if _modified_in_chain(index, chain, {c for c, _ in comps}):
        return None
    outer = {x.name for x in parse_modification(text, paren)[0]}
    if outer & {c for c, _ in comps}:
        return None
    return Plan(m.group(2), tuple(c for c, _ in comps), re.sub(r"\s+", " ", text[m.end():close]).strip())


def plans(index, model: str) -> list[tuple[Path, int, Plan]]:
    """(file, line, plan) of every class redeclaration among the classes *model* uses that
    :func:`plan` rewrites."""
    out = []
    for name in index.used_classes(model):
        info = index.classes[name]
        text = index.own_code(info, annotations=False)
        for m in _REDECL.finditer(text):
            p = plan(index, name, text, m.start())
            if p is not None:
                out.append((*index.location(info, m.start()), p))
    return out


def patches(index, model: str) -> dict[Path, Callable[[bytes], bytes]]:
    """For each file holding a redeclaration :func:`plans` finds: the edit writing its modification
    as one of the components (``= X, comp(mods)``), on the same line (lines kept)."""
    by_file: dict[Path, list[tuple[int, Plan]]] = {}
    for file, line, p in plans(index, model):
        by_file.setdefault(file, []).append((line, p))

    def patch_for(file: Path, todo: list[tuple[int, Plan]]) -> Callable[[bytes], bytes]:
        def patch(body: bytes) -> bytes:
            for line, p in sorted(todo, key=lambda t: -t[0]):
                code, _, _ = _code_mask(body)
                hits = [h for h in REDECLARATION.finditer(code) if h.group(2) == p.name.encode()
                        and body.count(b"\n", 0, h.start()) + 1 == line]
                close_at = _matching_paren(code, hits[0].end() - 1) if len(hits) == 1 else None
                if close_at is None:  # not as the index read it: the modification would be lost
                    raise UnsupportedConstructError(
                        f"unsupported Modelica construct in {model}: class redeclaration with a modification "
                        f"at {file}:{line}, where the text the front end reads differs from the library's")
                open_at = hits[0].end() - 1
                more = b"".join(b", " + c.encode() + b"(" + p.modification.encode() + b")" for c in p.components[1:])
                body = (body[:open_at] + b", " + p.components[0].encode() + body[open_at:close_at + 1] + more
                        + body[close_at + 1:])
                log.debug("%s:%d: redeclaration of %s read with its modification on %s", file, line, p.name,
                          ", ".join(p.components))
            return body
        return patch

    return {f: patch_for(f, todo) for f, todo in by_file.items()}
