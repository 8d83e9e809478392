"""``while`` statements given to rumoca as bounded ``for`` loops.

rumoca 0.10.2 accepts a ``while`` statement in a function only where it proves the loop finite
from a counter (``while i < n and ... loop ... i := i + 1``); any other (a bisection
``while hi - lo > tol``, Brent's ``while not found`` in ``Modelica.Math.Nonlinear``, the filter
normalisation of ``Modelica.Blocks``) is refused ("a statement without a checked DAE owner").
:func:`while_loops_as_for` rewrites every ::

    while COND loop BODY end while;

into ::

    for _while_pass_ in 1:N loop if COND then BODY end if; end for;
    assert(not (COND), "while loop at line L did not end within N passes");

with N = :data:`.while_loops.MAX_PASSES`, lines kept. Where the loop ends within N passes this is
the loop's meaning; where it would not, the assert stops the model (never a silently wrong value).
The embedded translator recognises the marked ``for`` loop and executes it as the ``while`` it was
(:mod:`.while_loops`: a constant condition iterates concretely, a bound is proved where the
condition turns constant false).
"""
from __future__ import annotations

import re

from .source_scan import _code_mask, _splice
from .while_loops import MAX_PASSES

MARKER = "_while_pass_"
"""The index of a ``for`` loop that was a ``while`` statement."""

_TOKEN = re.compile(rb"\bend\s+while\b|\bwhile\b")
_LOOP = re.compile(rb"\bloop\b")


def while_loops_as_for(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with each ``while`` statement rewritten (see the module's docstring), and the lines
    of the loops changed. A loop whose condition holds a string literal is left alone."""
    if b"while" not in data:
        return data, []
    code, _, _ = _code_mask(data)
    edits: list[tuple[int, int, bytes]] = []
    lines: list[int] = []
    stack: list[tuple[int, int, bytes] | None] = []
    for tok in _TOKEN.finditer(code):
        if tok.group(0) == b"while":
            loop = _LOOP.search(code, tok.end())
            if loop is None:
                return data, []
            cond = code[tok.end():loop.start()]
            if data[tok.end():loop.start()].count(b'"') or not cond.strip():
                stack.append(None)
                continue
            stack.append((tok.start(), loop.end(), b" ".join(cond.split())))
            continue
        if not stack:
            return data, []  # unbalanced: leave the file to the front end's own message
        opened = stack.pop()
        end = re.compile(rb"\s*;").match(code, tok.end())
        if opened is None or end is None:
            continue
        start, header_end, cond = opened
        line = data.count(b"\n", 0, start) + 1
        edits.append((start, header_end - start,
                      b"for " + MARKER.encode() + b" in 1:" + str(MAX_PASSES).encode() + b" loop if "
                      + data[start + 5:header_end - 4].strip() + b" then"))
        edits.append((tok.start(), end.end() - tok.start(),
                      b"end if; end for; assert(not (" + cond + b"), \"while loop at line " + str(line).encode()
                      + b" did not end within " + str(MAX_PASSES).encode() + b" passes\");"))
        lines.append(line)
    if not lines:
        return data, []
    return _splice(data, edits), lines
