"""Scanning Modelica source text as bytes: code without comments and strings, matching parentheses,
statement ends.

Shared by the source rewrites of :mod:`.rewrite` and the modules it calls (:mod:`.external_locals`,
:mod:`.streams_error`, :mod:`.if_asserts`, :mod:`.redeclare_short`), which therefore need not import
:mod:`.rewrite` itself.
"""
from __future__ import annotations

import re

# comments, string literals and quoted identifiers: never code
_NOT_CODE = re.compile(rb"//[^\n]*|/\*.*?(?:\*/|\Z)|\"(?:\\.|[^\"\\])*(?:\"|\Z)|'(?:\\.|[^'\\])*(?:'|\Z)", re.S)
_FUNCTION = re.compile(rb"\bfunction\s+([A-Za-z_]\w*)")


def _code_mask(data: bytes) -> tuple[bytes, list[int], list[int]]:
    """*data* with comments, strings and quoted identifiers blanked (newlines kept), and the
    start and end offsets of those blanked ranges."""
    starts: list[int] = []
    ends: list[int] = []

    def blank(match: re.Match[bytes]) -> bytes:
        starts.append(match.start())
        ends.append(match.end())
        return re.sub(rb"[^\n]", b" ", match.group(0))

    return _NOT_CODE.sub(blank, data), starts, ends


def _matching_paren(code: bytes, open_at: int) -> int | None:
    """Offset of the parenthesis closing the one at *open_at* in comment-free *code*."""
    depth = 0
    for k in range(open_at, len(code)):
        c = code[k : k + 1]
        if c == b"(":
            depth += 1
        elif c == b")":
            depth -= 1
            if depth == 0:
                return k
    return None


def _statement_end(code: bytes, at: int, stop: int) -> int | None:
    depth = 0
    for k in range(at, stop):
        c = code[k]
        if c in b"([{":
            depth += 1
        elif c in b")]}":
            depth -= 1
        elif c == 59 and depth == 0:  # ';'
            return k + 1
    return None


def _blank_comments(data: bytes, starts: list[int], ends: list[int]) -> bytes:
    out = bytearray(data)
    for s, e in zip(starts, ends):
        if data[s:s + 2] in (b"//", b"/*"):
            out[s:e] = re.sub(rb"[^\n]", b" ", data[s:e])
    return bytes(out)


def _splice(data: bytes, edits: list[tuple[int, int, bytes]]) -> bytes:
    """*data* with each edit ``(at, drop, new)`` applied: the *drop* bytes at offset *at* replaced by *new*
    (offsets into the original *data*; edits must not overlap)."""
    out = bytearray()
    pos = 0
    for at, drop, new in sorted(edits, key=lambda e: (e[0], e[1])):
        out += data[pos:at] + new
        pos = at + drop
    out += data[pos:]
    return bytes(out)
