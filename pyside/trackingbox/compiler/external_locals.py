"""Protected locals of ``external "FORTRAN 77"`` functions read by rumoca as trailing inputs.

The MSL's LAPACK wrappers (``Modelica.Math.Matrices.LAPACK.dgesv_vec`` and its kind) pass
protected locals (the work copy of ``A``, pivot and work arrays, leading dimensions) to the Fortran
routine. rumoca 0.10.2 refuses any such function ("passes protected local `Awork` to its external
body without a checked owner"), although it is valid Modelica. :func:`external_locals_as_inputs`
gives rumoca each of those locals as an ``input`` declared after the function's own inputs, with
the local's binding as its default (a local without one gets a zero of its type and size). For a
call that is valid Modelica this changes nothing: a call can only give the function's own inputs
(positionally or by name), so every moved local takes its default, which is the value it had
as a local. The embedded translator then sees the external call with every argument it names
evaluated, and gives the routine its meaning where it knows it (:mod:`.lapack`) or refuses the
function by name.

Only functions whose external language is ``"FORTRAN 77"`` are rewritten: the MSL's C functions
(tables, strings, files) are left to their own handling.
"""
from __future__ import annotations

import re

from .source_scan import _FUNCTION, _code_mask, _splice, _statement_end

_EXTERNAL_F77 = re.compile(rb'\bexternal\s*"FORTRAN 77"')
_DECL = re.compile(rb"\s*(?P<type>Real|Integer|Boolean)\s+(?P<name>[A-Za-z_]\w*)\s*")
_ZERO = {b"Real": b"0.0", b"Integer": b"0", b"Boolean": b"false"}


def _split_top(text: bytes) -> list[bytes]:
    """*text* split at its commas outside parentheses and brackets."""
    parts, depth, start = [], 0, 0
    for k, c in enumerate(text):
        if c in b"([{":
            depth += 1
        elif c in b")]}":
            depth -= 1
        elif c == 44 and depth == 0:  # ','
            parts.append(text[start:k].strip())
            start = k + 1
    parts.append(text[start:].strip())
    return parts


def _closing(code: bytes, at: int) -> int | None:
    """Offset just after the bracket or parenthesis closing the one at *at*."""
    depth = 0
    for k in range(at, len(code)):
        if code[k] in b"([{":
            depth += 1
        elif code[k] in b")]}":
            depth -= 1
            if depth == 0:
                return k + 1
    return None


def _as_input(code: bytes, data: bytes, start: int, stop: int) -> list[tuple[int, int, bytes]] | None:
    """The edits (offset, bytes dropped there, bytes put there) that make the declaration in ``code[start:stop]`` (up to its ``;``) an input
    with a default, or None when it is not a plain Real, Integer or Boolean component (*data*: the
    text with its strings, which *code* has blanked)."""
    m = _DECL.match(code, start, stop)
    if m is None:
        return None
    at = m.end()
    dims: list[bytes] = []
    if code[at:at + 1] == b"[":
        close = _closing(code, at)
        if close is None or close > stop:
            return None
        dims = [re.sub(rb"\s+", b" ", d) for d in _split_top(data[at + 1:close - 1])]
        if any(d in (b"", b":") for d in dims):
            return None
        at = close
    rest = code[at:stop]
    after = at
    if rest.lstrip().startswith(b"("):  # a modification: the default goes after it
        close = _closing(code, at + len(rest) - len(rest.lstrip()))
        if close is None or close > stop:
            return None
        after = close
    tail = code[after:stop].lstrip()
    edits = [(m.start("type"), 0, b"input ")]
    if tail.startswith(b"=") and not tail.startswith(b"=="):  # bound: the binding is the default
        # (zeros(n) is fill(0, n) by definition, MLS 10.3.3; rumoca 0.10.2 gives an Integer input
        # bound to zeros(...) the wrong shape, so it reads the fill)
        z = re.compile(rb"=\s*(zeros\s*\()").match(code, after + len(code[after:stop]) - len(tail))
        if z is not None and m.group("type") == b"Integer":
            edits.append((z.start(1), z.end(1) - z.start(1), b"fill(0, "))
        return edits
    if tail.strip(b" \t\r\n;"):  # anything but a (blanked) comment before the ';'
        return None
    zero = _ZERO[m.group("type")]
    edits.append((after, 0, b" = " + (b"fill(" + zero + b", " + b", ".join(dims) + b")" if dims else zero)))
    return edits


def external_locals_as_inputs(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with the protected locals of each ``external "FORTRAN 77"`` function declared as
    inputs after its own (see the module's docstring), and the lines of the functions changed.
    Lines are kept; byte offsets after an edit shift. A function whose protected section holds
    anything else than plain Real, Integer or Boolean declarations is left alone."""
    if b"FORTRAN 77" not in data:
        return data, []
    code, _, _ = _code_mask(data)
    edits: list[tuple[int, int, bytes]] = []
    lines: list[int] = []
    for ext in _EXTERNAL_F77.finditer(data):  # the language is a string, blanked in *code*
        if code[ext.start():ext.start() + 8] != b"external":  # in a comment or a string
            continue
        header = None
        for fn in _FUNCTION.finditer(code, 0, ext.start()):
            header = fn
        if header is None:
            continue
        body = code[header.end():ext.start()]
        prot = None
        for prot in re.finditer(rb"\bprotected\b", body):
            pass
        if prot is None or re.search(rb"\b(?:public|algorithm|equation|function)\b", body[prot.end():]):
            continue
        start, stop = header.end() + prot.end(), ext.start()
        found: list[tuple[int, int, bytes]] = []
        while code[start:stop].strip():
            end = _statement_end(code, start, stop)
            decl = _as_input(code, data, start, end) if end is not None else None
            if decl is None:
                found = []
                break
            found += decl
            start = end
        if found:
            at = header.end() + prot.start()
            edits.append((at, len(b"protected"), b" " * len(b"protected")))
            edits += found
            lines.append(data.count(b"\n", 0, header.start()) + 1)
    if not edits:
        return data, []
    return _splice(data, edits), lines
