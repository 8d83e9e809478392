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


def _blanked(text: bytes) -> bytes:
    """*text* with every byte but newlines turned into a space (the same length, the same lines)."""
    if b"\n" not in text:
        return b" " * len(text)
    return b"\n".join(b" " * len(part) for part in text.split(b"\n"))


_MASKS: dict[bytes, tuple[bytes, tuple[int, ...], tuple[int, ...]]] = {}
"""The last few masks made: each rewrite of :func:`.rewrite.frontend_bytes` masks the text again, and
most leave it as it was (a 430 kB ``Modelica/package.mo`` was masked 8 times, 0.7 s)."""


def _code_mask(data: bytes) -> tuple[bytes, list[int], list[int]]:
    """*data* with comments, strings and quoted identifiers blanked (newlines kept), and the
    start and end offsets of those blanked ranges."""
    found = _MASKS.get(data)
    if found is None:
        starts: list[int] = []
        ends: list[int] = []

        def blank(match: re.Match[bytes]) -> bytes:
            starts.append(match.start())
            ends.append(match.end())
            return _blanked(match.group(0))

        found = (_NOT_CODE.sub(blank, data), tuple(starts), tuple(ends))
        if len(_MASKS) >= 8:
            _MASKS.pop(next(iter(_MASKS)))
        _MASKS[data] = found
    return found[0], list(found[1]), list(found[2])


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
            out[s:e] = _blanked(data[s:e])
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
