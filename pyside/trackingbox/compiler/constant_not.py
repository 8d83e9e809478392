"""``not`` in the binding of a Boolean constant, read by rumoca as an if-expression.

rumoca 0.10.2 leaves a package constant unresolved where its binding applies ``not`` and a model of
the package reads it through a component: ``Modelica.Media.Incompressible.TableBased`` declares
``constant Boolean hasDensity = not (size(tableDensity,1)==0)``, its ``BaseProperties`` reads
``assert(hasDensity, ...)``, and ``Modelica.Fluid.Examples.IncompressibleFluidNetwork`` stopped at
"unresolved Flat reference `source.medium.hasDensity`". The same constant bound to
``size(tab,1) <> 0`` or to ``if size(tab,1) == 0 then false else true`` is read (measured on small
packages, ``tests/test_compiler_constant_not.py``).

``not r`` is true exactly where ``r`` is false (MLS 3.5), i.e. it is ``if r then false else true``.
:func:`constant_not_as_if` writes each ``not`` in the binding of a ``constant Boolean`` declaration
so, its operand being the relation that follows it (MLS grammar: ``logical-factor : [not]
relation``), which ends at the first ``and``, ``or``, ``then``, ``else``, ``elseif``, ``,``, ``;``,
``annotation`` or unmatched closing bracket. Lines are kept; byte offsets after an edit shift.
"""
from __future__ import annotations

import re

from .source_scan import _code_mask

_CONSTANT_BOOLEAN = re.compile(rb"\bconstant\s+Boolean\s+[A-Za-z_]\w*\s*(?:\[[^\];]*\]\s*)?=(?!=)")
_NOT = re.compile(rb"(?<![\w.])not\b")
_ENDS_OPERAND = re.compile(rb"\b(?:and|or|then|else|elseif|annotation|end|loop)\b|[,;]")


def _binding_end(code: bytes, pos: int) -> int:
    """Offset of the ``;`` (or ``annotation``) ending the binding that starts at *pos*."""
    depth = 0
    for m in re.finditer(rb"[(\[{]|[)\]}]|;|\bannotation\b", code[pos:]):
        tok = m.group(0)
        if tok in (b"(", b"[", b"{"):
            depth += 1
        elif tok in (b")", b"]", b"}"):
            depth -= 1
        elif depth <= 0:
            return pos + m.start()
    return len(code)


def _operand_end(code: bytes, data: bytes, pos: int, limit: int) -> int:
    """Offset of the last code byte, plus one, of the relation starting at *pos* (see the module
    docstring); a description string (blank in *code*, not in *data*) ends it too."""
    end = _relation_end(code, data, pos, limit)
    return pos + len(code[pos:end].rstrip())


def _relation_end(code: bytes, data: bytes, pos: int, limit: int) -> int:
    depth = 0
    k = pos
    while k < limit:
        ch = code[k:k + 1]
        if ch in (b"(", b"[", b"{"):
            depth += 1
        elif ch in (b")", b"]", b"}"):
            if depth == 0:
                return k
            depth -= 1
        elif depth == 0 and data[k:k + 1] == b'"':
            return k
        elif depth == 0:
            m = _ENDS_OPERAND.match(code, k)
            if m and (ch in (b",", b";") or not code[k - 1:k].isalnum() and code[k - 1:k] != b"_"):
                return k
        k += 1
    return limit


def constant_not_as_if(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with each ``not r`` in a Boolean constant's binding written ``(if r then false else
    true)``; and the lines changed (1-based)."""
    if b"not" not in data or b"constant" not in data:
        return data, []
    changed: set[int] = set()
    while True:  # the last 'not' of each binding per pass: its operand holds no other
        code, _, _ = _code_mask(data)
        edits: list[tuple[int, int, int]] = []  # (start of 'not', start of operand, end of operand)
        for decl in _CONSTANT_BOOLEAN.finditer(code):
            end = _binding_end(code, decl.end())
            found = [m for m in _NOT.finditer(code, decl.end(), end)]
            if found:
                stop = _operand_end(code, data, found[-1].end(), end)
                if code[found[-1].end():stop].strip():
                    edits.append((found[-1].start(), found[-1].end(), stop))
        if not edits:
            return data, sorted(changed)
        for at, start, stop in sorted(edits, reverse=True):
            changed.add(data.count(b"\n", 0, at) + 1)
            data = data[:at] + b"(if" + data[start:stop] + b" then false else true)" + data[stop:]
