"""``while`` statements given to rumoca as bounded ``for`` loops.

rumoca 0.10.2 accepts a ``while`` statement in a function where it proves the loop finite from a
counter (``while i < n and ... loop ... i := i + 1``, as in ``Modelica.Media``'s IF97 iterations);
any other (a bisection ``while hi - lo > tol``, Brent's ``while not found`` in
``Modelica.Math.Nonlinear``, the filter normalisation of ``Modelica.Blocks``) is refused ("a statement
without a checked DAE owner"). :func:`while_loops_as_for` rewrites each loop of the second kind (a
loop is left as it is where its condition compares a name with ``<`` or ``<=`` to a number or a
package constant and its body adds one to that name) ::

    while COND loop BODY end while;

into ::

    for _while_line_L in 1:N loop if COND then BODY end if; end for;
    assert(not (COND), "while loop at line L did not end within N passes");

with N = :data:`.while_loops.MAX_PASSES`, lines kept. A scalar output or protected local
(Real, Integer, Boolean, an ``SI`` type) declared without a value, which the loop assigns and
nothing assigns before it, is first set to zero (``u := 0.0;`` before the ``for``): rumoca refuses an
output left without a definition on a branch (Brent's ``u``, assigned only where the root is found)
and a local the loop carries without a value before it ("missing function value definition"); a
valid function never reads a variable before assigning it, so the zero is never seen. Where the loop ends within N passes this is
the loop's meaning  where it would not, the assert stops the model (never a silently wrong value).
The embedded translator recognises the marked ``for`` loop and executes it as the ``while`` it was
(:mod:`.while_loops`: a constant condition iterates concretely, a bound is proved where the
condition turns constant false).
"""
from __future__ import annotations

import re

from .source_scan import _code_mask, _splice
from .while_loops import MAX_PASSES

MARKER = "_while_line_"
"""The index of a ``for`` loop that was a ``while`` statement starts so, followed by the while's line
(``_while_line_25``): rumoca's spans are offsets into the rewritten text, which the file does not have."""

_TOKEN = re.compile(rb"\bend\s+while\b|\bwhile\b")
_LOOP = re.compile(rb"\bloop\b")
_COUNTED = re.compile(rb"\b([A-Za-z_]\w*)\s*<=?\s*(?:[0-9]|[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)")


def _counted(cond: bytes, body: bytes) -> bool:
    """Whether rumoca bounds the loop itself: *cond* compares a name ``i`` with ``<`` or ``<=`` to a
    number or a package constant (``IterationData.IMAX``) and *body* holds ``i := i + 1`` (an input
    as the bound is refused by rumoca, "does not have a proved finite arithmetic-series form")."""
    return any(re.search(rb"\b" + re.escape(m.group(1)) + rb"\s*:=\s*" + re.escape(m.group(1)) + rb"\s*\+\s*1\s*;",
                         body) for m in _COUNTED.finditer(cond))


_FUNCTION_HEAD = re.compile(rb"\bfunction\s+[A-Za-z_]\w*")
_DECL = re.compile(rb"(?:output\s+)?(Real|Integer|Boolean|(?:Modelica\.Units\.)?SI\.\w+)\s+([A-Za-z_]\w*)"
                   rb"\s*(?:\([^=]*\))?")
_ZERO = {b"Integer": b"0", b"Boolean": b"false"}


def _first_definitions(code: bytes, start: int, body: bytes) -> bytes:
    """``name := zero;`` for each scalar output or protected local (Real, Integer, Boolean, an
    ``SI`` type) of the function around offset *start*, declared without a value, that *body*
    assigns and that its algorithm does not assign before *start* (see the module's docstring)."""
    head = None
    for head in _FUNCTION_HEAD.finditer(code, 0, start):
        pass
    if head is None:
        return b""
    algorithm = re.compile(rb"\balgorithm\b").search(code, head.end(), start)
    if algorithm is None:
        return b""
    out = b""
    for stmt in code[head.end():algorithm.start()].split(b";"):
        words = stmt.split()
        while words and words[0] in (b"protected", b"public"):
            words = words[1:]
        decl = _DECL.fullmatch(b" ".join(words))
        if decl is None:
            continue
        kind, name = decl.group(1), decl.group(2)
        assigned = re.compile(rb"\b" + re.escape(name) + rb"\s*:=")
        if assigned.search(body) and not assigned.search(code, algorithm.end(), start):
            out += name + b" := " + _ZERO.get(kind, b"0.0") + b"; "
    return out


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
        if _counted(cond, code[header_end:tok.start()]):
            continue
        line = data.count(b"\n", 0, start) + 1
        # the condition as the code has it (a comment blanked, its newlines kept: the lines stay)
        header = (b"for " + MARKER.encode() + str(line).encode() + b" in 1:" + str(MAX_PASSES).encode()
                  + b" loop if" + code[start + 5:header_end - 4] + b"then")
        edits.append((start, header_end - start, _first_definitions(code, start, code[header_end:tok.start()]) + header))
        edits.append((tok.start(), end.end() - tok.start(),
                      b"end if; end for; assert(not (" + cond + b"), \"while loop at line " + str(line).encode()
                      + b" did not end within " + str(MAX_PASSES).encode() + b" passes\");"))
        lines.append(line)
    if not lines:
        return data, []
    return _splice(data, edits), lines
