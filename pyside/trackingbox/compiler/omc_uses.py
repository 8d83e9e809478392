"""The libraries a Modelica source declares it uses: ``annotation(uses(Lib(version="x.y.z")))``.

OpenModelica's ``loadFile`` does not reliably load what a class ``uses``; the
OpenModelica backend loads each declared library explicitly (``loadModel``)
before the source, so that a missing library or version gives one clear error.

The parser works on the source text: comments are blanked (strings are kept,
the version is one), every ``annotation(...)`` is read with balanced
parentheses (strings may hold parentheses), and only a ``uses(...)`` at the top
level of an annotation's argument list counts, so ``Documentation(info="...uses(...)...")``
or a ``uses`` nested in another modifier is not taken for one.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import CompileError
from .source import read_text, strip_comments

__all__ = ["LibraryUse", "library_uses", "merge_uses", "parse_uses", "source_uses"]


@dataclass(frozen=True)
class LibraryUse:
    """One entry of a ``uses`` annotation.

    Attributes
    ----------
    name:
        The library's top-level package name (``Modelica``).
    version:
        The version string (``"4.0.0"``), or ``None`` when the entry gives none.
    file:
        The file that declares the use.
    line:
        The 1-based line of the entry in *file*.
    """

    name: str
    version: str | None
    file: Path
    line: int

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"


_COMMENT = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\])*"', re.S)
_ANNOTATION = re.compile(r"\bannotation\s*\(")
_NAME = re.compile(r"[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*")


def _blank_comments(text: str) -> str:
    """Blank comments (not strings) keeping every offset and line."""

    def blank(match: re.Match[str]) -> str:
        token = match.group(0)
        if token.startswith('"'):
            return token
        return re.sub(r"[^\n]", " ", token)

    return _COMMENT.sub(blank, text)


def _closing(text: str, open_at: int) -> int:
    """Index of the parenthesis that closes the one at *open_at* (strings skipped); -1 if none."""
    depth = 0
    i = open_at
    n = len(text)
    while i < n:
        c = text[i]
        if c == '"':
            i += 1
            while i < n and text[i] != '"':
                i += 2 if text[i] == "\\" else 1
        elif c in "({[":
            depth += 1
        elif c in ")}]":
            depth -= 1
            if depth == 0:
                return i
        i += 1
    return -1


def _top_level_items(text: str, start: int, stop: int) -> list[tuple[int, int]]:
    """(start, stop) spans of the comma-separated items of ``text[start:stop]`` at depth 0."""
    items: list[tuple[int, int]] = []
    depth = 0
    i = item_start = start
    while i < stop:
        c = text[i]
        if c == '"':
            i += 1
            while i < stop and text[i] != '"':
                i += 2 if text[i] == "\\" else 1
        elif c in "({[":
            depth += 1
        elif c in ")}]":
            depth -= 1
        elif c == "," and depth == 0:
            items.append((item_start, i))
            item_start = i + 1
        i += 1
    items.append((item_start, stop))
    return [(a, b) for a, b in items if text[a:b].strip()]


def _unquote(literal: str) -> str:
    return re.sub(r"\\(.)", r"\1", literal[1:-1])


def parse_uses(text: str, file: Path | str = "<string>") -> tuple[LibraryUse, ...]:
    """The library uses declared in Modelica *text*, in order of appearance.

    Parameters
    ----------
    text:
        Modelica source text.
    file:
        The file the text comes from (for locations in errors).

    Returns
    -------
    tuple of LibraryUse

    Raises
    ------
    CompileError
        A ``uses`` annotation is malformed (unbalanced, an entry that is not
        ``Name`` or ``Name(version="...")``), naming the file and line.

    Examples
    --------
    >>> [(u.name, u.version) for u in parse_uses('package P annotation(uses(Modelica(version="4.0.0"))); end P;')]
    [('Modelica', '4.0.0')]
    """
    path = Path(file)
    code = _blank_comments(text)
    bare = strip_comments(text)  # strings blanked too: an "annotation(" inside a string is text
    found: list[LibraryUse] = []

    def line_of(offset: int) -> int:
        return code.count("\n", 0, offset) + 1

    for match in _ANNOTATION.finditer(bare):
        open_at = match.end() - 1
        close = _closing(code, open_at)
        if close < 0:
            raise CompileError(f"{path}:{line_of(match.start())}: unbalanced parentheses in annotation")
        for a, b in _top_level_items(code, open_at + 1, close):
            item = code[a:b]
            head = re.match(r"\s*uses\s*\(", item)
            if not head:
                continue
            uses_open = a + head.end() - 1
            uses_close = _closing(code, uses_open)
            if uses_close < 0 or uses_close > close:
                raise CompileError(f"{path}:{line_of(a)}: unbalanced parentheses in the uses annotation")
            for ea, eb in _top_level_items(code, uses_open + 1, uses_close):
                found.append(_entry(code[ea:eb], path, line_of(ea + len(code[ea:eb]) - len(code[ea:eb].lstrip()))))
    return tuple(found)


def _entry(entry: str, path: Path, line: int) -> LibraryUse:
    entry = entry.strip()
    name = _NAME.match(entry)
    if not name:
        raise CompileError(f"{path}:{line}: cannot read the uses entry {entry[:60]!r} "
                           f"(expected Name(version=\"x.y.z\"))")
    rest = entry[name.end():].strip()
    version: str | None = None
    if rest:
        if not (rest.startswith("(") and rest.endswith(")")):
            raise CompileError(f"{path}:{line}: cannot read the uses entry {entry[:60]!r} "
                               f"(expected {name.group(0)}(version=\"x.y.z\"))")
        for ma, mb in _top_level_items(rest, 1, len(rest) - 1):
            mod = re.fullmatch(r'\s*(\w+)\s*=\s*("(?:\\.|[^"\\])*")\s*', rest[ma:mb], re.S)
            if mod is None:
                raise CompileError(f"{path}:{line}: cannot read {rest[ma:mb].strip()[:60]!r} in the uses "
                                   f"entry of {name.group(0)} (expected version=\"x.y.z\")")
            if mod.group(1) == "version":
                version = _unquote(mod.group(2))
    return LibraryUse(name.group(0), version, path, line)


def source_uses(entry: Path) -> tuple[LibraryUse, ...]:
    """The uses of a source whose top-level file is *entry* (a ``.mo`` file or a ``package.mo``)."""
    return parse_uses(read_text(entry), entry)


def library_uses(library: Path) -> tuple[LibraryUse, ...]:
    """The uses of a ``--library`` package (a package directory or a ``.mo`` file)."""
    entry = library / "package.mo" if library.is_dir() else library
    if not entry.is_file():
        raise CompileError(f"library {library} has no package.mo: name a Modelica package directory or a .mo file")
    return source_uses(entry)


def merge_uses(uses: tuple[LibraryUse, ...] | list[LibraryUse], provided: set[str] | frozenset[str] = frozenset()
               ) -> tuple[LibraryUse, ...]:
    """One use per library, in first-seen order, leaving out the libraries in *provided*.

    *provided* are the top-level names loaded from files (the source itself and
    the ``--library`` packages). Two different versions of one library are an
    error naming both places; an entry without a version takes the versioned one.

    Raises
    ------
    CompileError
        Two uses ask for different versions of one library.
    """
    chosen: dict[str, LibraryUse] = {}
    for use in uses:
        if use.name in provided:
            continue
        seen = chosen.get(use.name)
        if seen is None or (seen.version is None and use.version is not None):
            chosen[use.name] = use
        elif use.version is not None and use.version != seen.version:
            raise CompileError(f"conflicting versions of library {use.name}: {seen.version!r} at {seen.where} "
                               f"and {use.version!r} at {use.where}; one OpenModelica session loads one version")
    return tuple(chosen.values())
