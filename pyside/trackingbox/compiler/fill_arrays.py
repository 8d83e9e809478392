"""``fill`` of an array, read by rumoca as the array comprehension it equals.

rumoca 0.10.2 refuses ``fill(c, 2)`` where ``c`` is an array ("canonical DAE construction rejected
an invalid operation: expression shape mismatch"): ``Real c[1] = {time}; Real cc[2, 1] = fill(c,
2);`` fails, and so does ``fill(x[1:1], 1)``; every ``Modelica.Fluid`` source does it with a medium
of substances or trace substances (``ports.C_outflow = fill(C, nPorts)``, ``ports.Xi_outflow =
fill(X[1:Medium.nXi], nPorts)``), which stopped ``RoomCO2``. It reads ``{c for tb__k in 1:2}``
right (shape [2, 1]).

``fill(s, n)`` is the array of *n* elements each equal to *s*, its size ``n`` followed by the sizes
of *s* (MLS 10.3.3), which is what the comprehension ``{s for k in 1:n}`` is (MLS 10.4.2.1), for a
scalar *s* as well. :func:`fill_arrays_as_comprehensions` writes so each two-argument ``fill`` whose
first argument is a component reference that is an array somewhere in the file (a slice such as
``X[1:n]``, or a name the file subscripts or declares with dimensions): the narrow case measured;
other ``fill`` calls are left as written. Lines are kept.
"""
from __future__ import annotations

import re

from .source_scan import _code_mask, _matching_paren

_FILL = re.compile(rb"(?<![\w.])fill\s*\(")
_REFERENCE = re.compile(rb"\s*([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)\s*(\[[^\[\]]*\])?\s*")
_ITERATOR = b"tb__k"


def _split(code: bytes, open_at: int, close_at: int) -> list[tuple[int, int]]:
    """Spans of the top-level arguments of the call whose parentheses are at *open_at*, *close_at*."""
    spans, depth, start = [], 0, open_at + 1
    for k in range(open_at + 1, close_at):
        c = code[k:k + 1]
        if c in (b"(", b"[", b"{"):
            depth += 1
        elif c in (b")", b"]", b"}"):
            depth -= 1
        elif c == b"," and depth == 0:
            spans.append((start, k))
            start = k + 1
    spans.append((start, close_at))
    return spans


def fill_arrays_as_comprehensions(body: bytes) -> tuple[bytes, list[int]]:
    """*body* with each ``fill(a, n)`` of an array ``a`` written ``{a for tb__k in 1:(n)}``
    (see the module), and the lines changed."""
    code, _, _ = _code_mask(body)
    if not _FILL.search(code) or _ITERATOR in code:
        return body, []
    arrays = set(re.findall(rb"(?<![\w.])([A-Za-z_]\w*)\s*\[", code))  # subscripted or declared with dimensions
    out, pos, lines = [], 0, []
    for m in _FILL.finditer(code):
        if m.start() < pos:
            continue
        close_at = _matching_paren(code, m.end() - 1)
        if close_at is None:
            continue
        args = _split(code, m.end() - 1, close_at)
        if len(args) != 2:
            continue
        ref = _REFERENCE.fullmatch(code, *args[0])
        if ref is None:
            continue
        sliced = ref.group(2) is not None and b":" in ref.group(2)
        if not sliced and (ref.group(2) is not None or ref.group(1).rsplit(b".", 1)[-1] not in arrays):
            continue
        (a0, a1), (n0, n1) = args
        out.append(body[pos:m.start()] + b"{" + body[a0:a1] + b" for " + _ITERATOR + b" in 1:(" + body[n0:n1]
                   + b")}")
        pos = close_at + 1
        lines.append(body.count(b"\n", 0, m.start()) + 1)
    if not lines:
        return body, []
    out.append(body[pos:])
    return b"".join(out), lines
