"""``Modelica.Utilities.Streams.error(message)`` read by rumoca as the assert it means.

``Streams.error`` (``external "C" ModelicaError``) stops the simulation with its message. rumoca
0.10.2 drops a call of a function without outputs in an equation section without a word, and
refuses one in a function ("calls ... as a statement without reading a result"), so the check the
library wrote would be lost or the model refused. :func:`streams_error_as_assert` has rumoca read
each call written with the function's full name as the assert with the same meaning:

* ``if c then Modelica.Utilities.Streams.error(m); end if;`` (the branch holding nothing else, no
  ``elseif``/``else``) as ``assert(not (c), m);``: rumoca also drops an assert inside an
  if-equation, and the condition in the assert is the same check;
* any other ``Modelica.Utilities.Streams.error(m);`` as ``assert(false, m);``;
* the same for ``error(m)`` in a class that imports ``Modelica.Utilities.Streams.error``
  (``Modelica.Math.Nonlinear.solveOneNonlinearEquation``).

A failing assert of level error stops the run with its message, as ``ModelicaError`` does. The
text keeps its lines and byte offsets (the replacement is padded with blanks).
"""
from __future__ import annotations

import re

from .source_scan import _code_mask, _matching_paren

_CALL = re.compile(rb"\bModelica\s*\.\s*Utilities\s*\.\s*Streams\s*\.\s*error\s*\(")
_IMPORT = re.compile(rb"\bimport\s+Modelica\s*\.\s*Utilities\s*\.\s*Streams\s*\.\s*error\s*;")
_HEAD = re.compile(rb"\b(?:function|model|block|class|package)\s+([A-Za-z_]\w*)")
_SHORT_CALL = re.compile(rb"(?<![\w.])error\s*\(")


def _pad(new: bytes, old: bytes) -> bytes:
    """*new* padded to the length and the line breaks of *old* (which must be longer)."""
    breaks = old.count(b"\n") - new.count(b"\n")
    body = new + b"\n" * breaks
    if breaks < 0 or len(body) > len(old):
        raise ValueError("replacement longer than the text it replaces")
    return body + b" " * (len(old) - len(body))


def _imported_regions(code: bytes) -> list[tuple[int, int]]:
    """(start, end) of each class body that holds ``import Modelica.Utilities.Streams.error;``, from
    the import to the class's ``end``: there a call ``error(...)`` names Streams.error."""
    regions = []
    for imp in _IMPORT.finditer(code):
        head = None
        for head in _HEAD.finditer(code, 0, imp.start()):
            pass
        if head is None:
            continue
        end = re.compile(rb"\bend\s+" + re.escape(head.group(1)) + rb"\s*;").search(code, imp.end())
        if end is not None:
            regions.append((imp.end(), end.start()))
    return regions


def streams_error_as_assert(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with each ``Modelica.Utilities.Streams.error`` call (written with its full name, or as
    ``error`` where the class imports it so) read as an assert (see the module's docstring), and
    the lines of the calls."""
    if b"Streams" not in data:
        return data, []
    code, _, _ = _code_mask(data)
    calls = list(_CALL.finditer(code))
    for start, stop in _imported_regions(code):
        calls += [m for m in _SHORT_CALL.finditer(code, start, stop)]
    out = bytearray(data)
    lines: list[int] = []
    for m in sorted(calls, key=lambda c: c.start()):
        close = _matching_paren(code, m.end() - 1)
        semi = re.compile(rb"\s*;").match(code, close + 1) if close is not None else None
        if semi is None:
            continue
        message = data[m.end():close]
        start, end = m.start(), semi.end()
        new = b"assert(false, " + message + b");"
        # the whole if-equation/statement around it: 'if c then' <call> 'end if;'
        window = max(0, start - 2000)
        before = re.search(rb"\bif\b((?:(?!\b(?:if|then|end|else|elseif)\b)[^;])*)\bthen\s*$", code[window:start])
        after = re.compile(rb"\s*end\s+if\s*;").match(code, end)
        if before is not None and after is not None:
            cond = data[window + before.start(1):window + before.end(1)].strip()
            new = b"assert(not (" + cond + b"), " + message + b");"
            start, end = window + before.start(), after.end()
        try:
            out[start:end] = _pad(new, data[start:end])
        except ValueError:
            continue
        lines.append(data.count(b"\n", 0, m.start()) + 1)
    return bytes(out), lines
