"""Class redeclarations with a modification, read by rumoca through a short class.

rumoca 0.10.2 drops the modification of a model (block, ...) redeclaration such as
``redeclare model HeatTransfer = IdealHeatTransfer(k = 4.9)``: the redeclared model keeps its own
``k``. It keeps it where the modified class is first declared as a short class
(``model HeatTransfer__tb27 = IdealHeatTransfer(k = 4.9)``) and the redeclaration names that
class, which means the same in Modelica: a short class definition is the class with the
modification applied (MLS 4.5.1), looked up in the same scope as the redeclaration's own
modification. :func:`short_class_redeclarations` does that for every such redeclaration whose
modification gives only literal values (numbers, Booleans, strings and arrays of them); rumoca
evaluates a name in a short class's modification to its value at translation, which would
freeze a tunable parameter, so a modification that refers to any name stays refused by
:mod:`.modifiers`.

A *function* redeclaration with a modification (``redeclare function flowCharacteristic =
quadraticFlow(V_flow_nominal = {...}, head_nominal = {...})``) is kept by rumoca as written (its
calls get the modified inputs) and is not rewritten; through a short class it would be lost.
"""
from __future__ import annotations

import re

from .source_scan import _blank_comments, _code_mask, _matching_paren, _splice

_KINDS = rb"(?:model|block|class|connector|record)"
REDECLARATION = re.compile(rb"\bredeclare\s+(?:(?:replaceable|final|each)\s+)*(" + _KINDS
                           + rb")\s+(\w+)\s*=\s*([\w.]+)\s*\(")
"""A class (not function or package) redeclaration with a modification, in comment-free code."""
_LITERAL_WORDS = {b"true", b"false", b"each", b"final"}
_CLASS_HEAD = re.compile(rb"(?:model|block|class|record|connector|package)\s+[A-Za-z_]\w*")


def literal_modification(code: bytes, open_at: int, close_at: int) -> bool:
    """Whether the modification ``code[open_at:close_at + 1]`` (comments and strings blanked)
    sets only element values given as literals: every name in it is an element being set
    (followed by ``=``) or ``true``, ``false``, ``each``, ``final``."""
    inner = code[open_at + 1:close_at]
    for m in re.finditer(rb"[A-Za-z_]\w*", inner):
        word = m.group(0)
        if word in _LITERAL_WORDS or re.match(rb"[eE]", word) and m.start() > 0 and inner[m.start() - 1:m.start()].isdigit():
            continue  # (the exponent of 1e-3)
        if not re.match(rb"\s*=(?!=)", inner[m.end():]):
            return False
    return b"(" not in inner


def _element_start(code: bytes, data: bytes, at: int) -> int | None:
    """Where the element (component declaration or extends clause) whose modification holds the
    redeclaration at *at* begins: just after the ``;``, ``public``, ``protected`` or class header
    (with its description) before it, outside every parenthesis enclosing *at*. None for a
    redeclaration that no parenthesis encloses (an element itself, left alone)."""
    depth = lowest = 0
    k = at
    while k > 0:
        k -= 1
        c = code[k:k + 1]
        if c in (b")", b"]", b"}"):
            depth += 1
        elif c in (b"(", b"[", b"{"):
            depth -= 1
            lowest = min(lowest, depth)
        elif lowest < 0 and depth == lowest:
            if c == b";":
                return k + 1
            if (k == 0 or not (code[k - 1:k].isalnum() or code[k - 1:k] == b"_")):
                word = re.match(rb"(?:public|protected)\b", code[k:k + 10])
                if word:
                    return k + word.end()
                head = _CLASS_HEAD.match(code, k)
                if head:
                    end = head.end()
                    rest = len(data[end:]) - len(data[end:].lstrip())
                    if data[end + rest:end + rest + 1] == b'"':  # the class's description
                        close = re.compile(rb'"(?:\\.|[^"\\])*"').match(data, end + rest)
                        end = close.end() if close else end
                    return end
    return None


def short_class_redeclarations(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with each class redeclaration whose modification is literal (see the module's
    docstring) redeclared to a short class declared just before the element holding it; and the
    lines of the redeclarations changed. Lines are kept; byte offsets after an edit shift."""
    if b"redeclare" not in data:
        return data, []
    code, starts, ends = _code_mask(data)
    clean = _blank_comments(data, starts, ends)  # (the strings kept: a literal may be one)
    edits: list[tuple[int, int, bytes]] = []
    lines: list[int] = []
    for m in REDECLARATION.finditer(code):
        open_at = m.end() - 1
        close_at = _matching_paren(code, open_at)
        if close_at is None or not literal_modification(code, open_at, close_at):
            continue
        start = _element_start(code, data, m.start())
        if start is None:
            continue
        line = data.count(b"\n", 0, m.start()) + 1
        name = m.group(2) + b"__tb%d_%d" % (line, m.start())
        original = clean[m.start(3):close_at + 1]
        short = b" " + m.group(1) + b" " + name + b" = " + re.sub(rb"\s*\n\s*", b" ", original).strip() + b"; "
        edits.append((start, 0, short))
        edits.append((m.start(3), close_at + 1 - m.start(3), name + b"\n" * original.count(b"\n")))
        lines.append(line)
    if not edits:
        return data, []
    return _splice(data, edits), lines


def short_class_handles(text: str, at: int) -> bool:
    """Whether the class redeclaration with a modification at offset *at* of the comment-free
    *text* (:mod:`.modifiers` reads classes so) is one :func:`short_class_redeclarations` rewrites."""
    code = text.encode()
    m = REDECLARATION.match(code, len(text[:at].encode()))
    if m is None:
        return False
    close_at = _matching_paren(code, m.end() - 1)
    return (close_at is not None and literal_modification(code, m.end() - 1, close_at)
            and _element_start(code, code, m.start()) is not None)
