"""An ``assert`` inside an if-equation, read by rumoca as the assert it means.

rumoca 0.10.2 drops an ``assert(...)`` written in a branch of an if-equation without a word, so a
model that should stop on it runs on. In Modelica the assert holds only while its branch is the
active one, which is the same as an assert outside the if-equation whose condition is
``if guard then (condition) else true``, the guard being the branch's own condition and the negation of the
conditions of the branches before it (``else``: of all of them), and of the branches around it
when if-equations are nested. :func:`if_asserts_outside` has rumoca read each such assert so:

* the assert inside the branch is blanked (its lines kept);
* each ``String(...)`` in its message is written ``"<...>"`` (rumoca 0.10.2 refuses ``String`` of
  an enumeration value, which an assert it drops never showed, e.g. ``Blocks.Continuous.Filter``;
  the FMU shows a message's values as ``<...>`` anyway);
* the assert with the guarded condition (its message and level as written) is written after the
  ``end if;`` of the outermost if-equation holding it, on that line; an if-equation holding nothing
  but asserts is replaced by them, padded to its length when they fit (then every byte offset of
  the file is kept; otherwise only its lines are).

In an initial equation section the guard starts with ``initial()`` (the FMU checks its asserts
while it is true). Only equation sections are read (an if-statement in an algorithm keeps its asserts in rumoca); an
assert in a ``when`` equation is left as it is.
"""
from __future__ import annotations

import re

from .source_scan import _code_mask, _matching_paren

_WORD = re.compile(rb"[A-Za-z_]\w*")
_SECTION = re.compile(rb"\bequation\b")
_CALL = re.compile(rb"([A-Za-z_]\w*(?:\s*\.\s*[A-Za-z_]\w*)*)\s*\(")
_KNOWN_CALLS = {b"assert", b"connect", b"terminate", b"reinit"}
_STOP = {b"algorithm", b"equation", b"initial", b"protected", b"public", b"annotation", b"external"}


class _Scan:
    """Walks an equation section of comment- and string-blanked *code*, collecting each assert in
    an if-equation with the conditions guarding it."""

    def __init__(self, code: bytes, text: bytes):
        self.code, self.text = code, text
        self.found: list[tuple[int, int, list[tuple[int, int, bool]], int]] = []  # assert span, guards, if
        self.ifs: dict[int, int] = {}  # outermost if-equation start -> end (after 'end if;')
        self.initial: set[int] = set()  # starts of the asserts found in initial equation sections
        self.calls: list[tuple[int, bytes]] = []  # call equations name(...); outside when-equations

    def word_at(self, pos: int) -> tuple[bytes, int, int]:
        m = re.compile(rb"\s*").match(self.code, pos)
        pos = m.end()
        w = _WORD.match(self.code, pos)
        return (w.group(0), pos, w.end()) if w else (b"", pos, pos)

    def statement_end(self, pos: int) -> int | None:
        """Offset after the ';' ending the statement starting at *pos* (parentheses balanced)."""
        depth = 0
        for k in range(pos, len(self.code)):
            c = self.code[k]
            if c in b"([{":
                depth += 1
            elif c in b")]}":
                depth -= 1
            elif c == 59 and depth <= 0:  # ';'
                return k + 1
        return None

    def keyword(self, pos: int, words: set[bytes]) -> tuple[bytes, int, int] | None:
        """The first of *words* at bracket depth 0 from *pos* (skipping if-expressions' own
        then/else), as (word, start, end)."""
        depth, nested = 0, 0
        for m in re.finditer(rb"[()\[\]{}]|[A-Za-z_]\w*", self.code[pos:]):
            tok = m.group(0)
            if tok in (b"(", b"[", b"{"):
                depth += 1
            elif tok in (b")", b"]", b"}"):
                depth -= 1
            elif depth == 0:
                if tok in words and not (nested and tok in (b"then", b"else", b"elseif")):
                    return tok, pos + m.start(), pos + m.end()
                if tok == b"if":
                    nested += 1
                elif tok == b"else" and nested:
                    nested -= 1
        return None

    def equations(self, pos: int, guards: list, in_when: bool, outer_if: int | None) -> tuple[int, bytes]:
        """Reads equations from *pos* to a word ending them; returns (its offset, the word)."""
        while True:
            word, start, end = self.word_at(pos)
            if not word or word in _STOP or word in (b"elseif", b"else", b"elsewhen"):
                return start, word
            if word == b"end":
                nxt, _, after = self.word_at(end)
                return start, (b"end " + nxt) if nxt in (b"if", b"for", b"when") else b"end"
            if word == b"if":
                pos = self.if_equation(start, guards, in_when, outer_if)
            elif word in (b"for", b"when"):
                head = self.keyword(end, {b"loop"} if word == b"for" else {b"then"})
                if head is None:
                    raise _Unreadable
                inner = guards + [(end, head[1], None)] if guards and word == b"for" else guards
                pos, stop = self.equations(head[2], inner, in_when or word == b"when", outer_if)
                while stop == b"elsewhen":
                    head = self.keyword(pos + len(stop), {b"then"})
                    if head is None:
                        raise _Unreadable
                    pos, stop = self.equations(head[2], guards, True, outer_if)
                if stop != b"end " + word:
                    raise _Unreadable
                pos = self.statement_end(pos)
            else:
                stop = self.statement_end(start)
                if stop is None:
                    raise _Unreadable
                if word == b"assert" and guards and not in_when:
                    self.found.append((start, stop, list(guards), outer_if))
                call = _CALL.match(self.code, start)
                if call and call.group(1) not in _KNOWN_CALLS and not call.group(1).startswith(b"Connections") \
                        and not in_when:
                    close = _matching_paren(self.code, call.end() - 1)
                    if close is not None and self.code[close + 1:stop].strip() == b";":
                        self.calls.append((start, re.sub(rb"\s", b"", call.group(1))))
                pos = stop
            if pos is None:
                raise _Unreadable

    def if_equation(self, start: int, guards: list, in_when: bool, outer_if: int | None) -> int:
        outer = start if outer_if is None else outer_if
        before: list[tuple[int, int]] = []  # conditions of the earlier branches
        pos, word = start + 2, b"if"
        while True:
            if word in (b"if", b"elseif"):
                head = self.keyword(pos, {b"then"})
                if head is None:
                    raise _Unreadable
                cond = (pos, head[1])
                branch = [(a, b, True) for a, b in before] + [(cond[0], cond[1], False)]
                before.append(cond)
                pos, word = self.equations(head[2], guards + branch, in_when, outer)
            elif word == b"else":
                pos, word = self.equations(pos + 4, guards + [(a, b, True) for a, b in before], in_when, outer)
            elif word == b"end if":
                end = self.statement_end(pos)
                if end is None:
                    raise _Unreadable
                if outer_if is None:
                    self.ifs[start] = end
                return end
            else:
                raise _Unreadable
            if word in (b"elseif", b"else"):
                pos = self.word_at(pos)[1] + (0 if word == b"else" else 6)


class _Unreadable(Exception):
    """A section the scanner does not follow: left as it is."""


def _one_line(text: bytes, quoted: bytes) -> bytes:
    """*text* (comments blanked) on one line: each run of blanks outside strings (*quoted* is 1
    inside them) as one blank, a line break inside a string as ``\\n``."""
    out = bytearray()
    for k, c in enumerate(text):
        if not quoted[k]:
            if chr(c).isspace():
                if out and out[-1:] != b" ":
                    out += b" "
            else:
                out.append(c)
        elif c == 10:
            out += b"\\n"
        elif c != 13:
            out.append(c)
    return bytes(out).strip()


def _guarded(scan: _Scan, start: int, stop: int, guards) -> bytes:
    """``assert(if (g1) and not (g2) ... then (condition) else true, rest)`` for the assert at
    start:stop (the condition is read only where its branch is active, as in the if-equation)."""
    text, code = scan.text, scan.code
    open_at = code.index(b"(", start)
    close = _matching_paren(code, open_at)
    depth, comma = 0, None
    for k in range(open_at + 1, close):
        c = code[k]
        depth += c in b"([{"
        depth -= c in b")]}"
        if c == 44 and depth == 0:  # ','
            comma = k
            break
    if comma is None:
        raise _Unreadable
    def line(a: int, b: int) -> bytes:
        return _one_line(text[a:b], scan.quoted[a:b])

    guard = b" and ".join((b"not (%s)" if neg else b"(%s)") % line(a, b) for a, b, neg in guards if neg is not None)
    if start in scan.initial:  # checked at initialisation only, as an initial equation is
        guard = b"initial() and " + guard
    loops = [line(a, b) for a, b, neg in guards if neg is None]  # for-loops inside the if
    rest, at = [], comma + 1  # the message (and level), each String(...) in it as "<...>"
    for m in re.finditer(rb"\bString\s*\(", code[comma + 1:close]):
        start_s = comma + 1 + m.start()
        if start_s < at:
            continue
        end_s = _matching_paren(code, comma + m.end())
        rest += [line(at, start_s), b'"<...>"']
        at = end_s + 1
    rest.append(line(at, close))
    new = b"assert(if " + guard + b" then (" + line(open_at + 1, comma) + b") else true, " + b" ".join(rest) + b");"
    for head in reversed(loops):
        new = b"for " + head + b" loop " + new + b" end for;"
    return new


def if_asserts_outside(data: bytes) -> tuple[bytes, list[int]]:
    """*data* with each assert in an if-equation read as the assert it means outside it (see the
    module's docstring), and the lines of those asserts."""
    if b"assert" not in data:
        return data, []
    code, starts, ends = _code_mask(data)
    text = bytearray(data)  # comments blanked, strings kept
    quoted = bytearray(len(data))
    for a, b in zip(starts, ends):
        if data[a:a + 2] in (b"//", b"/*"):
            text[a:b] = re.sub(rb"[^\n]", b" ", data[a:b])
        else:
            quoted[a:b] = b"\1" * (b - a)
    scan = _Scan(code, bytes(text))
    scan.quoted = bytes(quoted)
    for m in _SECTION.finditer(code):
        before = len(scan.found)
        try:
            scan.equations(m.end(), [], False, None)
        except (_Unreadable, ValueError, TypeError):
            continue
        if re.search(rb"\binitial\s*$", code[max(0, m.start() - 40):m.start()]):  # an initial equation
            scan.initial.update(start for start, *_ in scan.found[before:])
    if not scan.found:
        return data, []
    by_if: dict[int, list] = {}
    for start, stop, guards, outer in scan.found:
        by_if.setdefault(outer, []).append((start, stop, guards))
    out = bytearray(data)
    lines: list[int] = []
    edits: list[tuple[int, int, bytes]] = []
    for outer, asserts in by_if.items():
        end = scan.ifs.get(outer)
        if end is None:
            continue
        try:
            new = b" ".join(_guarded(scan, s, e, g) for s, e, g in asserts)
        except _Unreadable:
            continue
        region = bytearray(scan.text[outer:end])
        for s, e, _ in asserts:
            region[s - outer:e - outer] = re.sub(rb"[^\n]", b" ", bytes(region[s - outer:e - outer]))
        rest = _code_mask(bytes(region))[0]
        only_asserts = re.fullmatch(rb"\s*if\b.*", rest, re.S) is not None and not re.search(
            rb"=|\b(?:connect|assert|terminate)\s*\(|\b[A-Za-z_][\w.]*\s*\([^;]*\)\s*;", _strip_heads(rest))
        if only_asserts:
            old = data[outer:end]
            body = new + b"\n" * old.count(b"\n")
            edits.append((outer, end, body + b" " * max(0, len(old) - len(body))))
        else:
            edits.append((outer, end, bytes(region) + b" " + new))
        lines += [data.count(b"\n", 0, s) + 1 for s, _, _ in asserts]
    for start, end, new in sorted(edits, reverse=True):
        out[start:end] = new
    return bytes(out), sorted(lines)


def call_equations(data: bytes) -> list[tuple[int, str]]:
    """(line, name) of each call equation ``name(...);`` in an equation section outside a
    ``when`` (other than assert, connect, terminate and the ``Connections`` operators): rumoca 0.10.2 drops such a call of a function
    without outputs, the asserts in its body included (e.g. ``Modelica.Fluid.Utilities.checkBoundary``)."""
    if b"equation" not in data:
        return []
    code = _code_mask(data)[0]
    scan = _Scan(code, code)
    for m in _SECTION.finditer(code):
        try:
            scan.equations(m.end(), [], False, None)
        except (_Unreadable, ValueError, TypeError):
            continue
    return [(data.count(b"\n", 0, at) + 1, name.decode()) for at, name in scan.calls]


def _strip_heads(code: bytes) -> bytes:
    """*code* of an if-equation without its conditions (``if``/``elseif`` ... ``then``), which may
    hold '=' or calls of their own."""
    return re.sub(rb"\b(?:if|elseif)\b.*?\bthen\b", b" ", code, flags=re.S)


__all__ = ["call_equations", "if_asserts_outside"]
