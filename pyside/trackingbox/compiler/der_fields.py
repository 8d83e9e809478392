"""``der`` of a field of an array of components, read by rumoca element by element.

rumoca 0.10.2 refuses ``der(mediums.h)`` where ``mediums`` is an array of components
(``Medium.BaseProperties[n] mediums`` in ``Modelica.Fluid.Interfaces.PartialDistributedVolume``'s
initial equation ``der(mediums.h) = zeros(n)``, taken with ``Dynamics.SteadyStateInitial``): "der(...)
must have exactly one resolved variable-reference operand". In Modelica ``mediums.h`` is the array
``{mediums[1].h, ..., mediums[n].h}`` (MLS 10.6.1 slicing of component arrays) and ``der`` of an array is
the array of the elements' derivatives (MLS 3.7.4), so ``der(mediums.h)`` is the comprehension
``{der(mediums[k].h) for k in 1:size(mediums, 1)}``, which rumoca reads.
:func:`component_array_der` writes it so where the component's declaration in the same file is a
one-dimensional array (``T[n] a`` or ``T a[n]``, every declaration of that name in the file so);
anything else is left as written. Lines are kept; byte offsets after an edit shift.
"""
from __future__ import annotations

import re

from .source_scan import _code_mask

_DER_FIELD = re.compile(rb"\bder\s*\(\s*([A-Za-z_]\w*)\.([A-Za-z_]\w*)\s*\)")
_INDEX = b"k__tb"


def _one_dimensional(code: bytes, name: bytes) -> bool:
    """Whether every declaration of component *name* in comment-free *code* is a one-dimensional
    array (and there is one)."""
    n = re.escape(name)
    found = False
    for m in re.finditer(rb"(?<![\w.])[A-Za-z_][\w.]*\s*(\[[^\];]*\])?\s+" + n + rb"\b\s*(\[[^\];]*\])?\s*[(;=\"]",
                         code):
        head = m.group(0).split()[0]
        if head in (b"end", b"der", b"connect", b"for", b"in", b"if", b"then", b"else", b"return"):
            continue
        dims = [d for d in (m.group(1), m.group(2)) if d]
        if len(dims) != 1 or b"," in dims[0]:
            return False
        found = True
    return found


def component_array_der(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with ``der(a.b)`` of a one-dimensional array of components ``a`` read element by
    element (see the module); and the lines changed."""
    if b"der" not in data:
        return data, []
    code = _code_mask(data)[0]
    edits: list[tuple[int, int, bytes]] = []
    lines: list[int] = []
    verdict: dict[bytes, bool] = {}
    for m in _DER_FIELD.finditer(code):
        name, field = m.group(1), m.group(2)
        if name not in verdict:
            verdict[name] = _one_dimensional(code, name)
        if not verdict[name]:
            continue
        new = (b"{der(" + name + b"[" + _INDEX + b"]." + field + b") for " + _INDEX + b" in 1:size("
               + name + b", 1)}")
        edits.append((m.start(), m.end() - m.start(), new))
        lines.append(data.count(b"\n", 0, m.start()) + 1)
    if not edits:
        return data, []
    out = bytearray()
    pos = 0
    for at, drop, new in edits:
        out += data[pos:at] + new
        pos = at + drop
    out += data[pos:]
    return bytes(out), lines
