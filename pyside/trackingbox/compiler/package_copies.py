"""A short package class that modifies a package, read by rumoca through a copy of that package with
the modification in its ``extends`` clause.

With ``package Medium = Modelica.Media.Air.MoistAir(extraPropertiesNames = {"CO2"}, C_nominal =
{1.519E-3})`` handed to a component (``redeclare package Medium = Medium``), rumoca 0.10.2 loses the
functions MoistAir redeclares: a source's ``Medium.setState_pTX(p, T, X)`` stays
``PartialMedium.setState_pTX`` ("unresolved Flat reference"), whatever the modification
(``T_default = 290`` as well) and in the long form (``package Medium extends MoistAir(...); end
Medium;``) too; the same package without a modification is read right. A package of the library
whose own ``extends`` clause carries the modification is read right as well (measured on the
front-end tree of a ``FixedBoundary`` with modified MoistAir; ``tests/test_compiler_moist_air.py``).

In Modelica the two mean the same where the modification only sets elements the package inherits
(MLS 7.2.4: the short class's modification applies to the inherited elements; in the ``extends``
clause it does too, and nothing in between sets them): :func:`patches` gives the front end, for each
such short class among the classes a model uses, a copy of the package (its file's text, as the
front end reads it), renamed ``<Name>__tb<digest>``, with the modification added to its one
``extends`` clause, placed in its enclosing package (so every name in it is looked up as in the
original), and has the short class name the copy. It does so only where

* the modification gives literal values only (as :mod:`.redeclare_short`: a name would be looked
  up in the copy's scope instead of the short class's),
* the package is a long class alone in its own file (``Air/MoistAir.mo``) with one ``extends``
  clause, its enclosing package a ``package.mo``,
* the package declares none of the modified elements itself, and its ``extends`` clause modifies
  none of them.

Anything else is left as written (rumoca's refusal stands, naming the construct).
"""
from __future__ import annotations

import hashlib
import logging
import re
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from .redeclare_short import literal_modification
from .source_scan import _code_mask, _matching_paren

log = logging.getLogger(__name__)

_SHORT = re.compile(rb"\bpackage\s+([A-Za-z_]\w*)\s*=\s*([A-Za-z_][\w.]*)\s*\(")
_EXTENDS = re.compile(rb"(?<![\w.])extends\s+[\w.]+\s*(\()?")


class Copy(NamedTuple):
    user: Path  # file of the short class
    line: int  # its line there
    name: str  # the short class's simple name
    package: str  # the full name of the package it modifies
    copy: str  # the simple name of the copy
    modification: bytes  # the modification's text, without its parentheses


def _elements(modification: bytes) -> set[str]:
    """Names the modification sets at its top level."""
    out, depth, start = set(), 0, 0
    for k in range(len(modification) + 1):
        c = modification[k:k + 1]
        if c in (b"(", b"[", b"{"):
            depth += 1
        elif c in (b")", b"]", b"}"):
            depth -= 1
        elif depth == 0 and c in (b",", b""):
            m = re.match(rb"\s*(?:(?:each|final)\s+)*([A-Za-z_]\w*)\s*=(?!=)", modification[start:k])
            if m:
                out.add(m.group(1).decode())
            start = k + 1
    return out


def _copyable(index, package: str, names: set[str]) -> bool:
    info = index.classes.get(package)
    if info is None or info.short or info.kind != "package" or info.file.stem != info.simple:
        return False
    parent = index.classes.get(info.parent or "")
    if parent is None or parent.file.name != "package.mo" or parent.file.parent != info.file.parent:
        return False
    own = index.own_code(info, annotations=False)
    clauses = list(re.finditer(r"(?<![\w.])extends\s+[\w.]+\s*(\()?", own))
    if len(clauses) != 1 or len(info.extends) != 1:
        return False
    for name in names:
        declared = rf"(?<![\w.])[A-Za-z_][\w.]*\s*(?:\[[^\];]*\]\s*)?(?<=[\s\]]){re.escape(name)}\s*[\[(=;]"
        if re.search(declared, re.sub(r"(?<![\w.])extends\s+[\w.]+\s*\([^;]*", "", own)):
            return False  # declared here (or possibly: refused as before)
        if clauses[0].group(1) and re.search(rf"[(,]\s*(?:(?:each|final)\s+)*{re.escape(name)}\s*[=(]",
                                             own[clauses[0].start():own.find(";", clauses[0].start())]):
            return False
    return True


def plans(index, model: str) -> list[Copy]:
    """The short package classes among *model*'s classes that are read through a copy (see the module)."""
    out = []
    for cls in index.used_classes(model):
        for child in index.children.get(cls, {}).values():
            info = index.classes[child]
            if not (info.short and info.kind == "package"):
                continue
            data = info.file.read_bytes()
            code, _, _ = _code_mask(data)
            m = _SHORT.search(code, info.start, info.end + 1)
            if m is None or m.group(1).decode() != info.simple:
                continue
            open_at = m.end() - 1
            close_at = _matching_paren(code, open_at)
            if close_at is None or not literal_modification(code, open_at, close_at):
                continue
            modification = data[open_at + 1:close_at]
            if b"redeclare" in modification:
                continue
            target = index.lookup(m.group(2).decode(), cls)
            names = _elements(code[open_at + 1:close_at])
            if target is None or not names or not _copyable(index, target, names):
                continue
            digest = hashlib.sha256(target.encode() + b"\0" + modification).hexdigest()[:8]
            out.append(Copy(info.file, data.count(b"\n", 0, m.start()) + 1, info.simple, target,
                            f"{target.rsplit('.', 1)[-1]}__tb{digest}", modification))
    return out


def _copy_text(index, p: Copy, read: Callable[[Path], bytes]) -> bytes:
    """The package's file as the front end reads it, renamed and with the modification in its extends clause."""
    info = index.classes[p.package]
    data = read(info.file)
    code, _, _ = _code_mask(data)
    simple = info.simple.encode()
    head = re.search(rb"\bpackage\s+(" + simple + rb")\b", code)
    end = list(re.finditer(rb"\bend\s+(" + simple + rb")\s*;", code))
    ext = _EXTENDS.search(code, head.end() if head else 0)
    if head is None or not end or ext is None:
        raise ValueError(f"{info.file}: package {info.simple} not as the index read it")
    new = p.copy.encode()
    tail = end[-1]
    body = (data[head.end(1):ext.end()] + (p.modification + b", " if ext.group(1) else b"(" + p.modification + b")")
            + data[ext.end():tail.start(1)] + new + data[tail.end(1):tail.end()])
    return data[head.start():head.start(1)] + new + body


def patches(index, model: str, read: Callable[[Path], bytes]) -> dict[Path, Callable[[bytes], bytes]]:
    """Per file, the edit: the short class names the copy (lines kept), the enclosing package's
    ``package.mo`` holds the copy before its ``end``. *read*: a file as the front end reads it."""
    found = plans(index, model)
    out: dict[Path, list[Callable[[bytes], bytes]]] = {}
    for p in found:
        def rename(body: bytes, p=p) -> bytes:
            code, _, _ = _code_mask(body)
            for m in _SHORT.finditer(code):
                if m.group(1).decode() == p.name and body.count(b"\n", 0, m.start()) + 1 == p.line:
                    close_at = _matching_paren(code, m.end() - 1)
                    base = m.group(2)
                    replaced = base + b"__tb" + p.copy.rsplit("__tb", 1)[1].encode()
                    lines = b"\n" * body.count(b"\n", m.start(2), close_at)
                    return body[:m.start(2)] + replaced + lines + body[close_at + 1:]
            return body
        out.setdefault(p.user, []).append(rename)
        parent = index.classes[index.classes[p.package].parent]
        text = _copy_text(index, p, read)

        def insert(body: bytes, parent=parent, text=text) -> bytes:
            code, _, _ = _code_mask(body)
            end = list(re.finditer(rb"\bend\s+" + parent.simple.encode() + rb"\s*;", code))
            if not end or text in body:
                return body
            at = end[-1].start()
            for a in re.finditer(rb"(?<![\w.])annotation\s*\(", code):  # the class's annotation comes last
                close = _matching_paren(code, a.end() - 1)
                if close is not None and re.fullmatch(rb"\s*;\s*", code[close + 1:at]):
                    at = a.start()
            return body[:at] + text + b"\n" + body[at:]
        out.setdefault(parent.file, []).append(insert)
        log.debug("%s:%d: package %s read through a copy of %s with its modification in the extends clause",
                  p.user, p.line, p.name, p.package)

    def chain(edits):
        def patch(body: bytes) -> bytes:
            for edit in edits:
                body = edit(body)
            return body
        return patch
    return {f: chain(edits) for f, edits in out.items()}
