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
anything else is left as written.

The same ``der`` of an element of a component array indexed by a for-equation's variable
(``for i in 1:n loop der(mediums[i].Xi) = zeros(Medium.nXi); end for;``, the same file, for
``substanceDynamics = SteadyStateInitial``) is refused alike. A for-equation holding one equation
``lhs = rhs`` stands for that equation for each value of the index (MLS 8.3.3), i.e. for the array
equation ``{lhs for i in 1:n} = {rhs for i in 1:n}``; where the left-hand side is such a
``der(a[i].b)``, in an initial equation section, and the right-hand side ``0`` or ``zeros(k)`` (the
steady starts of ``Modelica.Fluid``), the loop is written ``{der(a[i].b) for i in 1:n} = zeros(n, k)``
(:func:`_loop_as_array_equation`; other forms rumoca reads wrong, see there). Lines are kept; byte offsets after an edit shift.
"""
from __future__ import annotations

import re

from .source_scan import _code_mask

_DER_FIELD = re.compile(rb"\bder\s*\(\s*([A-Za-z_]\w*)\.([A-Za-z_]\w*)\s*\)")
_INDEX = b"k__tb"
_LOOP_DER = re.compile(rb"\bfor\s+([A-Za-z_]\w*)\s+in\s+([^;]*?)\s+loop(\s+)(der\s*\(\s*[A-Za-z_]\w*\s*\[\s*\1\s*\]"
                       rb"\s*\.\s*[A-Za-z_]\w*\s*\))(\s*)=(?!=)([^;]*);(\s*)end\s+for\s*;")
"""A for-equation whose body is the one equation ``der(a[i].b) = rhs`` (comment-free text)."""


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


_SECTION = re.compile(rb"\b(?:initial\s+equation|initial\s+algorithm|equation|algorithm|end\s+(?!(?:for|if|when|while)\b)[A-Za-z_]\w*\s*;)")


def _loop_as_array_equation(code: bytes, data: bytes, m: re.Match[bytes]) -> bytes | None:
    """The array equation standing for the for-equation *m* (see the module), or None to leave it:
    only in an initial equation section, over ``1:E``, with a right-hand side ``0`` or ``zeros(...)``
    (rumoca 0.10.2 reads an array comprehension on the right-hand side with the wrong shape, and
    counts such equations in an equation section wrong: measured, ``tests/test_compiler_der_fields.py``)."""
    index, rng = m.group(1), m.group(2)
    lhs, rhs = m.group(4), m.group(6).strip()
    if data[m.start():m.end()] != m.group(0):
        return None  # (a comment or string inside: left as written)
    sections = [s.group(0) for s in _SECTION.finditer(code, 0, m.start())]
    if not sections or not re.fullmatch(rb"initial\s+equation", sections[-1]):
        return None
    upper = re.fullmatch(rb"1\s*:\s*([^:]+)", rng.strip())
    if upper is None or re.search(rb"\b" + re.escape(index) + rb"\b", rhs):
        return None
    if re.fullmatch(rb"0(?:\.0*)?", rhs):
        right = b"zeros(" + upper.group(1).strip() + b")"
    else:
        zeros = re.fullmatch(rb"zeros\s*\(([^()]*(?:\([^()]*\)[^()]*)*)\)", rhs)
        if zeros is None:
            return None
        right = b"zeros(" + upper.group(1).strip() + b", " + zeros.group(1).strip() + b")"
    new = b"{" + lhs + b" for " + index + b" in " + rng.strip() + b"} = " + right + b";"
    return new + b"\n" * (m.group(0).count(b"\n") - new.count(b"\n"))


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
    for m in _LOOP_DER.finditer(code):
        new = _loop_as_array_equation(code, data, m)
        if new is not None:
            edits.append((m.start(), m.end() - m.start(), new))
            lines.append(data.count(b"\n", 0, m.start()) + 1)
    if not edits:
        return data, []
    edits.sort()
    out = bytearray()
    pos = 0
    for at, drop, new in edits:
        out += data[pos:at] + new
        pos = at + drop
    out += data[pos:]
    return bytes(out), lines
