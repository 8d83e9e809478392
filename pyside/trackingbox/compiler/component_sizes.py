"""The size of an array of components given by another component's parameter, given to rumoca as
its number where the declarations fix it.

rumoca 0.10.2 sizes the variables of ``FixedHeatFlow[pipe8.nNodes] heat8`` but instantiates the
class's equations once for the whole array, so the model comes back "unbalanced"
(``Modelica.Fluid.Examples.IncompressibleFluidNetwork``; :func:`.embedded._component_sized_array`
names the construct where it stays). The same array sized by a number is read right.

A parameter's value is what its declaration binds it to unless a modification changes it (MLS 7.2).
:func:`patches` writes the size as that number, in the model's own class (no class outside can
modify its components: it is the model compiled), where it can be sure of it:

* the component (``pipe8``) is declared in the model's own class, not as an array, and its
  declaration gives the parameter an integer literal (``DynamicPipe pipe8(nNodes = 4)``: the
  outermost modification) or does not modify it, and then
* its class (``DynamicPipe``, looked up from the model) or a base of it declares the parameter as
  ``parameter Integer name[(...)] = <integer literal>``, and neither that class nor any of its bases
  names the parameter in a modification (``extends Base(nNodes = 3)``, ``(final nNodes = n)``, which
  would give another value: refused as before).

The number stands where ``comp.param`` stood, padded with blanks (lines and byte offsets kept).
"""
from __future__ import annotations

import logging
import re
from collections.abc import Callable
from pathlib import Path

from .modification_parse import parse_modification
from .record_constants import declaration, own_text

log = logging.getLogger(__name__)

_SIZED = re.compile(r"(?<![\w.])[A-Za-z_][\w.]*\s*\[\s*(?P<ref>(?P<comp>[A-Za-z_]\w*)\.(?P<param>[A-Za-z_]\w*))"
                    r"\s*\]\s*(?P<name>[A-Za-z_]\w*)\s*[(;]")
_GIVEN = re.compile(r"(?:(?:each|final)\s+)*[A-Za-z_]\w*\s*=\s*(\d+)\s*(?=[,)])")
_NUM = r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_SCALED = re.compile(rf"(?:final\s+)?(?P<name>[A-Za-z_]\w*)\s*=\s*(?:(?P<n1>{_NUM})\s*\*\s*(?P<a1>[A-Za-z_][\w.]*)"
                     rf"|(?P<a2>[A-Za-z_][\w.]*)\s*\*\s*(?P<n2>{_NUM}))\s*(?=[,)])")
"""``name = number*array`` or ``name = array*number`` (comment-free text)."""
_INDEX = "k__tb"
_INTEGER = re.compile(r"\s*=\s*(\d+)\s*(?:;|annotation\b|$)")


def _declared_integer(index, cls: str, param: str, codes: dict[str, str]) -> int | None:
    """The integer literal the declaration of parameter *param* in class *cls* or its bases binds it
    to, where no class of that chain modifies an element of that name; else None."""
    chain = index.ancestors(cls)
    modified = re.compile(rf"[(,]\s*(?:(?:each|final|redeclare)\s+)*{re.escape(param)}\s*(?:\(|=(?!=))")
    if any(modified.search(own_text(index, c, codes)) for c in chain):
        return None
    found = declaration(index, cls, param, codes)
    if found is None:
        return None
    owner, m = found
    if "parameter" not in m.group("prefix").split() or m.group("type") != "Integer":
        return None
    code = own_text(index, owner, codes)
    pos = m.end() - 1
    if m.group("after") == "(":
        _, pos = parse_modification(code, pos)
    value = _INTEGER.match(code, pos)
    return int(value.group(1)) if value else None


def sizes(index, model: str) -> list[tuple[int, str, int]]:
    """(offset in the model's own text, ``comp.param``, its value) of each array of components in
    *model*'s own class sized by a component's parameter whose value the declarations fix."""
    info = index.classes.get(model)
    if info is None:
        return []
    codes: dict[str, str] = {}
    code = own_text(index, model, codes)
    out = []
    for hit in _SIZED.finditer(code):
        comp, param = hit.group("comp"), hit.group("param")
        found = declaration(index, model, comp, codes)
        if found is None or found[0] != model:
            continue
        _, decl = found
        if "[" in decl.group(0)[len(decl.group("prefix")) + len(decl.group("type")):]:
            continue  # an array of components: comp.param is an array
        given = [mod for mod in parse_modification(code, decl.end() - 1)[0] if mod.name == param] \
            if decl.group("after") == "(" else []
        target = index.lookup(decl.group("type"), model)
        if target is None or len(given) > 1:
            continue
        if given:  # the declaration's own modification: the outermost one (the model is compiled)
            literal = _GIVEN.match(code, given[0].offset)
            value = int(literal.group(1)) if literal and given[0].has_value and not given[0].subs else None
        else:
            value = _declared_integer(index, target, param, codes)
        if value is not None and len(str(value)) <= len(hit.group("ref")):
            out.append((hit.start("ref"), hit.group("ref"), value, _scaled(code, hit)))
    return out


def _scaled(code: str, hit: re.Match) -> list[tuple[str, str, str]]:
    """(element, number, array) of each element of the array's own modification given as
    ``number*array`` or ``array*number``, without ``each``."""
    if code[hit.end() - 1] != "(":
        return []
    found = []
    for mod in parse_modification(code, hit.end() - 1)[0]:
        if not mod.has_value or mod.subs or code.startswith("each", mod.offset):
            continue
        value = _SCALED.match(code, mod.offset)
        if value and value.group("name") == mod.name:
            number = value.group("n1") or value.group("n2")
            found.append((mod.name, number, value.group("a1") or value.group("a2")))
    return found


def patches(index, model: str) -> dict[Path, Callable[[bytes], bytes]]:
    """For the model's file: the edit writing each size :func:`sizes` finds as its number, and each
    ``q = number*array`` of such an array's modification as ``q = {number*array[k] for k in 1:size}``
    (rumoca 0.10.2 stops at "expression shape mismatch" on the product there; in Modelica the
    element ``h[k].q`` takes ``(number*array)[k]``, MLS 7.2.5)."""
    found = sizes(index, model)
    if not found:
        return {}
    info = index.classes[model]
    by_line: dict[int, list[tuple[str, int, list[tuple[str, str, str]]]]] = {}
    for offset, ref, value, scaled in found:
        by_line.setdefault(index.location(info, offset)[1], []).append((ref, value, scaled))

    def patch(body: bytes) -> bytes:
        lines = body.split(b"\n")
        for line, refs in sorted(by_line.items(), reverse=True):
            if line > len(lines):
                continue
            for ref, value, scaled in refs:
                pattern = re.compile(rb"\[\s*" + re.escape(ref.encode()) + rb"\s*\]")
                if len(pattern.findall(lines[line - 1])) != 1:
                    continue  # the line is not as the index read it: left as written
                lines[line - 1] = pattern.sub(
                    lambda m: m.group(0).replace(ref.encode(), str(value).encode().ljust(len(ref))), lines[line - 1])
                log.debug("%s:%d: %s read by the front end as %d", info.file, line, ref, value)
                if scaled:
                    lines[line - 1:] = _comprehensions(b"\n".join(lines[line - 1:]), value, scaled).split(b"\n")
        return b"\n".join(lines)

    return {info.file: patch}


def _comprehensions(text: bytes, size: int, scaled: list[tuple[str, str, str]]) -> bytes:
    """*text* (from the array's declaration on) with the first ``name = number*array`` of each of
    *scaled* written as a comprehension over 1:*size*, its line breaks kept after it."""
    for name, number, array in scaled:
        n, a = re.escape(number.encode()), re.escape(array.encode())
        found = re.compile(rb"(?<![\w.])" + re.escape(name.encode()) + rb"\s*=\s*(?:" + n + rb"\s*\*\s*" + a + rb"|"
                           + a + rb"\s*\*\s*" + n + rb")(?![\w.\[])").search(text)
        if found is None:
            continue
        new = (f"{name} = {{{number}*{array}[{_INDEX}] for {_INDEX} in 1:{size}}}".encode()
               + b"\n" * found.group(0).count(b"\n"))
        text = text[:found.start()] + new + text[found.end():]
    return text
