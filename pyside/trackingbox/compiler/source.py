"""Modelica source handling shared by the backends.

Resolves what the user named (a ``.mo`` file or a package directory), lists the
files that belong to it, finds the ``experiment`` annotation of a class, and
locates constructs in the text (file and line) so that errors can say where a
construct stands even when the flattened model no longer carries positions.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import CompileError


@dataclass(frozen=True)
class ModelicaSource:
    """A Modelica source as the user named it.

    Attributes
    ----------
    entry:
        The file a compiler loads: the ``.mo`` file, or ``package.mo`` of a
        package directory.
    root:
        The directory that holds the source tree (top-level package directory's
        parent for a package, the file's directory for a single file).
    files:
        Every ``.mo`` file of the source, sorted.
    """

    entry: Path
    root: Path
    files: tuple[Path, ...]


def resolve_source(source: str | Path) -> ModelicaSource:
    """Resolve a ``.mo`` file or a package directory into a :class:`ModelicaSource`."""
    path = Path(source).expanduser()
    if not path.exists():
        raise CompileError(f"Modelica source {str(path)!r} does not exist")
    path = path.resolve()
    if path.is_dir():
        entry = path / "package.mo"
        if not entry.is_file():
            raise CompileError(
                f"{path} is a directory without package.mo: name a .mo file or a Modelica package directory"
            )
        files = tuple(sorted(path.rglob("*.mo")))
        return ModelicaSource(entry=entry, root=path.parent, files=files)
    if path.suffix != ".mo":
        raise CompileError(f"Modelica source {str(path)!r} is not a .mo file or a package directory")
    if path.name == "package.mo":
        files = tuple(sorted(path.parent.rglob("*.mo")))
        return ModelicaSource(entry=path, root=path.parent.parent, files=files)
    return ModelicaSource(entry=path, root=path.parent, files=(path,))


_COMMENT_OR_STRING = re.compile(r'//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\])*"', re.S)


def strip_comments(text: str) -> str:
    """Blank out comments and string literals, keeping line structure."""

    def blank(match: re.Match[str]) -> str:
        return re.sub(r"[^\n]", " ", match.group(0))

    return _COMMENT_OR_STRING.sub(blank, text)


@dataclass(frozen=True)
class Location:
    file: Path
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"


def find_construct(files: tuple[Path, ...], pattern: str, limit: int = 5) -> list[Location]:
    """Locations (file, line) where the regular expression *pattern* matches code.

    Comments and strings are ignored. At most *limit* locations are returned.
    """
    regex = re.compile(pattern)
    found: list[Location] = []
    for file in files:
        try:
            text = strip_comments(file.read_text(encoding="utf-8", errors="replace"))
        except OSError:
            continue
        for match in regex.finditer(text):
            found.append(Location(file, text.count("\n", 0, match.start()) + 1))
            if len(found) >= limit:
                return found
    return found


def class_file(source: ModelicaSource, model: str) -> Path | None:
    """The file that defines the class *model* (``Pkg.Sub.Model``), if found."""
    short = model.rsplit(".", 1)[-1]
    pattern = re.compile(
        rf"\b(?:model|block|class|package|connector|record|function)\s+{re.escape(short)}\b"
    )
    candidates = [f for f in source.files if f.stem == short] + list(source.files)
    for file in candidates:
        try:
            text = strip_comments(file.read_text(encoding="utf-8", errors="replace"))
        except OSError:
            continue
        if pattern.search(text):
            return file
    return None


_EXPERIMENT = re.compile(r"experiment\s*\(([^()]*)\)", re.S)
_KEYVAL = re.compile(r"(StartTime|StopTime|Tolerance|Interval)\s*=\s*([-+0-9.eE]+)")


def experiment_settings(source: ModelicaSource, model: str) -> dict[str, float]:
    """``StartTime``/``StopTime``/``Tolerance``/``Interval`` of the class's experiment annotation."""
    file = class_file(source, model)
    if file is None:
        return {}
    text = file.read_text(encoding="utf-8", errors="replace")
    short = model.rsplit(".", 1)[-1]
    start = re.search(rf"\b(?:model|block|class)\s+{re.escape(short)}\b", text)
    end = re.search(rf"\bend\s+{re.escape(short)}\s*;", text)
    body = text[start.start() if start else 0 : end.end() if end else len(text)]
    settings: dict[str, float] = {}
    for match in _EXPERIMENT.finditer(body):
        for key, value in _KEYVAL.findall(match.group(1)):
            try:
                settings[key] = float(value)
            except ValueError:
                pass
    return settings


_CLASS_DECL = re.compile(r"\b(?:model|block|class|package|connector|record|function)\s+([A-Za-z_]\w*)")


def class_names(source: ModelicaSource) -> list[str]:
    """Dotted names of the classes the source declares (for "did you mean" messages)."""
    names: set[str] = set()
    for file in source.files:
        try:
            rel = file.relative_to(source.root)
        except ValueError:
            continue
        parts = list(rel.with_suffix("").parts)
        if parts and parts[-1] == "package":
            parts = parts[:-1]
        prefix = ".".join(parts[:-1]) if len(source.files) > 1 or source.entry.name == "package.mo" else ""
        try:
            text = strip_comments(file.read_text(encoding="utf-8", errors="replace"))
        except OSError:
            continue
        declared = _CLASS_DECL.findall(text)
        if not declared:
            continue
        top = ".".join(p for p in (prefix, declared[0]) if p)
        names.add(top)
        for inner in declared[1:]:
            names.add(f"{top}.{inner}")
    return sorted(names)
