"""Discrete fan-outs to array elements, read by the front end as the equations they mean.

rumoca 0.10.2 turns a connection set into a chain of equalities between its members and orients
each Boolean or Integer equality as an assignment by the members' distance from the set's
producer, per variable rather than per array element. Where one output feeds several inputs and
one of them is an element of an input array (the MSL's ``BooleanNetwork1``:
``connect(booleanPulse2.y, and1.u[3])`` beside ``connect(booleanPulse2.y, rising.u)``), the chain
can hold an equality between two inputs at the same distance, which it cannot orient: "element
assignments must cover a discrete coordinate exactly once", and the model was refused.

For a connector that is a Boolean or Integer ``input``/``output`` of a simple type (``connector
BooleanInput = input Boolean``), ``connect(a, b)`` contributes the equation ``a = b`` and nothing
else (MLS 9.2: the members of a set of non-flow variables are equal). So in the model's own
equations, each connection between an output (or an input of the model itself) that feeds several
inputs and an element of an input array is given to the front end as that equation, the input on
its left side (``and1.u[3] = booleanPulse2.y``), which rumoca orients as the element's
assignment. The other connections of the set stay connections. The connect statement's bytes are
replaced by the equation padded with blanks: lines and offsets stay where they are, and the
annotation after it stays the equation's own.

Only the model's own class text is read and changed, and only connections whose two ends resolve
(by Modelica's lookup, :class:`.library.LibraryIndex`) to components of the model declared with
connector classes of that simple form; anything else is left as written.
"""
from __future__ import annotations

import logging
import re
from collections import Counter
from collections.abc import Callable
from pathlib import Path

from .library import KEYWORDS
from .source_scan import _code_mask, _matching_paren, _splice

log = logging.getLogger(__name__)

_CONNECT = re.compile(rb"\bconnect\s*\(")
_REF = re.compile(r"([A-Za-z_]\w*)\.([A-Za-z_]\w*)(\[\s*\d+\s*\])?")
_SIMPLE = re.compile(r"=\s*(input|output)\s+(Boolean|Integer)\b(?!\s*\.)")
_SHORT_BASE = re.compile(r"=\s*(?:(input|output)\s+)?([A-Za-z_][\w.]*)\s*(?:\[[^\]]*\])?\s*(?:\(|\"|annotation\b|;|$)")


def _declared_type(index, cls: str, name: str) -> tuple[str, str] | None:
    """The type name of component *name* of class *cls* (declared there or inherited) and the class
    whose text declares it."""
    pattern = re.compile(r"(?<![\w.])([A-Za-z_][\w.]*)\s*(?:\[[^\]]*\]\s*)?\s+" + re.escape(name)
                         + r"\s*(?=[\[(;]|\bif\b|\bannotation\b|$)", re.M)
    seen: set[str] = set()
    todo = [cls]
    while todo:
        c = todo.pop(0)
        if c in seen or c not in index.classes:
            continue
        seen.add(c)
        own = index.own_code(index.classes[c], annotations=False)
        for m in pattern.finditer(own):
            if m.group(1) not in KEYWORDS:
                return m.group(1), c
        todo.extend(index.bases(c))
    return None


def _signal(index, type_name: str, scope: str) -> tuple[str, str] | None:
    """(causality, Boolean|Integer) of a connector class of the form ``connector X = input Boolean``
    (through further short classes, each ``= [input|output] Name``), else None."""
    causality = None
    cls = index.lookup(type_name, scope)
    for _ in range(6):
        info = index.classes.get(cls) if cls else None
        if info is None or not info.short:
            return None
        text = " ".join(index.code(info).split())
        simple = _SIMPLE.search(text)
        if simple:
            return causality or simple.group(1), simple.group(2)
        base = _SHORT_BASE.search(text)
        if base is None:
            return None
        causality = causality or base.group(1)
        cls = index.lookup(base.group(2), info.parent or "")
    return None


def _resolve(index, model: str, ref: str) -> tuple[str, str] | None:
    """(causality, type) of ``component.connector`` in *model*, or None where either end is not a
    simple discrete connector of a component declared with a class the index knows."""
    m = _REF.fullmatch(ref)
    if m is None:
        return None
    comp = _declared_type(index, model, m.group(1))
    if comp is None:
        return None
    comp_cls = index.lookup(comp[0], comp[1])
    if comp_cls is None:
        return None
    member = _declared_type(index, comp_cls, m.group(2))
    if member is None:
        return None
    return _signal(index, member[0], member[1])


def _connects(code: bytes, lo: int, hi: int) -> list[tuple[int, int, str, str]]:
    """``(start, end, a, b)`` of the connect statements in *code*[lo:hi] (blanks removed from a, b)."""
    out = []
    for m in _CONNECT.finditer(code, lo, hi):
        close = _matching_paren(code, m.end() - 1)
        if close is None or close > hi:
            continue
        args = code[m.end():close].decode("utf-8", "replace")
        depth, cut = 0, None
        for k, ch in enumerate(args):
            depth += ch in "([{"
            depth -= ch in ")]}"
            if ch == "," and depth == 0:
                cut = k
                break
        if cut is None:
            continue
        a, b = ("".join(s.split()) for s in (args[:cut], args[cut + 1:]))
        out.append((m.start(), close + 1, a, b))
    return out


def _class_range(code: bytes, short: str) -> tuple[int, int] | None:
    name = re.escape(short.encode())
    heads = list(re.finditer(rb"\b(?:model|block|class)\s+" + name + rb"\b", code))
    ends = list(re.finditer(rb"\bend\s+" + name + rb"\s*;", code))
    if len(heads) != 1 or len(ends) != 1 or ends[0].start() < heads[0].end():
        return None
    return heads[0].end(), ends[0].start()


def equations_for(index, model: str) -> dict[tuple[str, str], str]:
    """The model's own connections to be read as equations: ``(a, b)`` as written -> ``lhs = rhs``."""
    info = index.classes.get(model)
    if info is None:
        return {}
    own = index.own_code(info, annotations=False).encode()
    found = _connects(own, 0, len(own))
    if not any("[" in a or "[" in b for _, _, a, b in found):
        return {}
    uses = Counter(side for _, _, a, b in found for side in (a, b) if "[" not in side)
    out: dict[tuple[str, str], str] = {}
    for _, _, a, b in found:
        if ("[" in a) == ("[" in b):
            continue
        element, other = (a, b) if "[" in a else (b, a)
        if uses[other] < 2 or not _REF.fullmatch(element) or not _REF.fullmatch(other):
            continue  # not a fan-out: rumoca orients a single connection
        e, o = _resolve(index, model, element), _resolve(index, model, other)
        if e is None or o is None or e[1] != o[1]:
            continue
        if e[0] == "input":
            out[(a, b)] = f"{element} = {other}"
        elif o[0] == "input" and e[0] == "output":
            out[(a, b)] = f"{other} = {element}"
    return out


def patches(index, model: str) -> dict[Path, Callable[[bytes], bytes]]:
    """For the file of *model*: the edit that reads its discrete fan-outs to array elements as
    equations (see the module), or nothing."""
    wanted = equations_for(index, model)
    if not wanted:
        return {}
    info = index.classes[model]

    def patch(body: bytes) -> bytes:
        code = _code_mask(body)[0]
        where = _class_range(code, info.simple)
        if where is None:
            return body  # the class is not found once in what the front end reads: left as written
        edits = []
        for start, end, a, b in _connects(code, *where):
            new = wanted.get((a, b))
            if new is None:
                continue
            old = body[start:end]
            lines = old.count(b"\n")
            text = new.encode()
            edits.append((start, end - start, text + b" " * (len(old) - len(text) - lines) + b"\n" * lines))
        if edits:
            log.debug("%s: %d discrete connection(s) to array elements read as equations by the front end",
                      info.file, len(edits))
        return _splice(body, edits)

    return {info.file: patch}
