"""Modelica source handling shared by the backends.

Resolves what the user named (a ``.mo`` file or a package directory), lists the
files that belong to it, finds the ``experiment`` annotation of a class, and
locates constructs in the text (file and line) so that errors can say where a
construct stands even when the flattened model no longer carries positions.
"""
from __future__ import annotations

import functools
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


def blanked(text: str) -> str:
    """*text* with every character but newlines turned into a space (the same length, the same lines)."""
    if "\n" not in text:
        return " " * len(text)
    return "\n".join(" " * len(part) for part in text.split("\n"))


def strip_comments(text: str) -> str:
    """Blank out comments and string literals, keeping line structure."""

    def blank(match: re.Match[str]) -> str:
        return blanked(match.group(0))

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
            text = strip_comments(read_text(file))
        except OSError:
            continue
        for match in regex.finditer(text):
            found.append(Location(file, text.count("\n", 0, match.start()) + 1))
            if len(found) >= limit:
                return found
    return found


def class_file(source: ModelicaSource, model: str) -> Path | None:
    """The file that defines the class *model* (``Pkg.Sub.Model``), if found."""
    exact = _file_of(source, model)
    if exact is not None:
        return exact
    short = model.rsplit(".", 1)[-1]
    pattern = re.compile(
        rf"\b(?:model|block|class|package|connector|record|function)\s+{re.escape(short)}\b"
    )
    candidates = [f for f in source.files if f.stem == short] + list(source.files)
    for file in candidates:
        try:
            text = strip_comments(read_text(file))
        except OSError:
            continue
        if pattern.search(text):
            return file
    return None


BOM = b"\xef\xbb\xbf"


def read_text(file: Path) -> str:
    """The text of a ``.mo`` file, a leading byte-order mark removed."""
    return file.read_text(encoding="utf-8-sig", errors="replace")


def has_bom(file: Path) -> bool:
    """Whether *file* starts with a UTF-8 byte-order mark (rumoca refuses those)."""
    try:
        with open(file, "rb") as fh:
            return fh.read(3) == BOM
    except OSError:
        return False


_DECL_OF = r"\b(?:(?:partial|encapsulated|final|replaceable|redeclare|expandable|operator|pure|impure)\s+)*" \
           r"(?:model|block|class|package|connector|record|function|type)\s+{name}\b"


@functools.lru_cache(maxsize=4096)
def _code_cached(file: Path, mtime_ns: int, size: int) -> str:
    return strip_comments(read_text(file))


def _code(file: Path) -> str:
    """The text of *file* without comments and strings (cached while the file is unchanged)."""
    try:
        st = file.stat()
    except OSError:
        return ""
    return _code_cached(file, st.st_mtime_ns, st.st_size)


def _declares(text: str, name: str) -> re.Match[str] | None:
    return re.search(_DECL_OF.format(name=re.escape(name)), text)


_CLASS_HEAD = re.compile(
    r"\b(?:(?:partial|encapsulated|final|replaceable|redeclare|expandable|operator|pure|impure|inner|outer)\s+)*"
    r"(?:model|block|class|package|connector|record|function|type)\s+(?:extends\s+)?([A-Za-z_]\w*)")
_CLASS_END = re.compile(r"\bend\s+([A-Za-z_]\w*)\s*;")


@functools.lru_cache(maxsize=1024)
def class_ranges(code: str) -> tuple[tuple[tuple[str, ...], int, int], ...]:
    """Every long class definition of comment-free *code*: (nested path, start, end) in characters.

    The path holds the names of the enclosing classes of the file and the class's own name
    (``("Pkg", "Model")`` for a model inside a package of the same file). Short class
    definitions (``type T = Real;``) and partial applications (``function f(x = 1)``) enclose
    nothing and are left out; ``end name;`` closes the innermost open class of that name.
    """
    events = sorted([(m.start(), 0, m.group(1), m.end()) for m in _CLASS_HEAD.finditer(code)
                     if not re.match(r"\s*[=(]", code[m.end():])]
                    + [(m.start(), 1, m.group(1), m.end()) for m in _CLASS_END.finditer(code)])
    stack: list[tuple[str, int]] = []
    found: list[tuple[tuple[str, ...], int, int]] = []
    for pos, kind, name, end in events:
        if kind == 0:
            stack.append((name, pos))
            continue
        names = [n for n, _ in stack]
        if name not in names:
            continue  # end for; end if; end when; ...
        k = len(names) - 1 - names[::-1].index(name)
        found.append((tuple(names[: k + 1]), stack[k][1], end))
        del stack[k:]
    for k, (name, pos) in enumerate(stack):  # unterminated: to the end of the text
        found.append((tuple(n for n, _ in stack[: k + 1]), pos, len(code)))
    return tuple(sorted(found, key=lambda r: r[1]))


def _class_range(code: str, dotted: str) -> tuple[int, int] | None:
    """Character range of the class *dotted* (``Pkg.Sub.Model``, or a suffix of it) in comment-free
    *code*: the definition whose nested path is the longest suffix of *dotted* (the first such one)."""
    parts = tuple(dotted.split("."))
    best: tuple[int, int] | None = None
    depth = 0
    for path, start, end in class_ranges(code):
        if len(path) > depth and parts[-len(path):] == path:
            best, depth = (start, end), len(path)
    return best


def class_lines(file: Path, dotted: str) -> tuple[int, int] | None:
    """First and last line of the definition of class *dotted* (or a suffix of it) in *file*."""
    code = _code(Path(file))
    rng = _class_range(code, dotted)
    if rng is None:
        return None
    return code.count("\n", 0, rng[0]) + 1, code.count("\n", 0, rng[1]) + 1


def class_extent(source: ModelicaSource, model: str) -> tuple[Path, int, int] | None:
    """The file of class *model* and the first and last line of its definition there."""
    file = _file_of(source, model)
    if file is None:
        return None
    lines = class_lines(file, model)
    return None if lines is None else (file, *lines)


def _file_of(source: ModelicaSource, dotted: str) -> Path | None:
    """The file that declares the class *dotted* (``Pkg.Sub.Model``) in *source*, by Modelica's
    file mapping (``Pkg/Sub/Model.mo``, ``Pkg/Sub/package.mo``, or a class nested in a file)."""
    parts = dotted.split(".")
    if source.entry.name != "package.mo":  # a single file: every class is in it
        text = _code(source.entry)
        return source.entry if _declares(text, parts[-1]) else None
    cur = source.root
    holder: Path | None = None
    for k, part in enumerate(parts):
        if (cur / part / "package.mo").is_file():
            cur = cur / part
            holder = cur / "package.mo"
            continue
        if (cur / f"{part}.mo").is_file():
            file = cur / f"{part}.mo"
            rest = parts[k:]
        elif holder is not None:
            file, rest = holder, parts[k:]
        else:
            return None
        text = _code(file)
        return file if all(_declares(text, p) for p in rest) else None
    return holder


def span_location(span: dict | None, files: tuple[Path, ...], expect: str | None = None) -> Location | None:
    """The file and line of a rumoca ``span`` (``{"source", "start", "end"}``, byte offsets).

    rumoca names a span's file by an opaque number, so the file is the first of *files*
    (the model's own files, see :func:`.library.model_files`) whose text at the span matches the
    regular expression *expect* (or is merely long enough when *expect* is None).
    """
    if not isinstance(span, dict) or not isinstance(span.get("start"), int):
        return None
    start, end = int(span["start"]), int(span.get("end", span["start"]))
    for file in files:
        try:
            data = file.read_bytes()
        except OSError:
            continue
        if data.startswith(BOM):
            data = data[3:]
        if end > len(data):
            continue
        if expect is not None:
            snippet = data[start:max(end, start + 80)].decode("utf-8", "replace")
            if not re.match(expect, snippet):
                continue
        return Location(file, data.count(b"\n", 0, start) + 1)
    return None


def span_sources(flat: dict, files: tuple[Path, ...]) -> dict[int, Path]:
    """Which of *files* each of rumoca's span source numbers stands for.

    Learnt from the flat model's variables: a variable's declaration span starts
    with its own name in the file it is declared in.
    """
    texts: dict[Path, bytes] = {}
    for file in files:
        try:
            data = file.read_bytes()
        except OSError:
            continue
        texts[file] = data[3:] if data.startswith(BOM) else data
    found: dict[int, Path] = {}
    for var in (flat.get("variables") or {}).values():
        if not isinstance(var, dict):
            continue
        parts = (var.get("component_ref") or {}).get("parts") or []
        span = var.get("source_span")
        if not parts or not isinstance(span, dict) or span.get("source") in found:
            continue
        ident = str(parts[-1].get("ident", "")).encode()
        start = span.get("start")
        if not ident or not isinstance(start, int):
            continue
        hits = [f for f, data in texts.items() if data[start:start + len(ident)] == ident]
        if len(hits) == 1:
            found[span["source"]] = hits[0]
    return found


_EXPERIMENT = re.compile(r"experiment\s*\(([^()]*)\)", re.S)
_KEYVAL = re.compile(r"(StartTime|StopTime|Tolerance|Interval)\s*=\s*([-+0-9.eE]+)")


def experiment_settings(source: ModelicaSource, model: str) -> dict[str, float]:
    """``StartTime``/``StopTime``/``Tolerance``/``Interval`` of the class's experiment annotation."""
    file = class_file(source, model)
    if file is None:
        return {}
    text = read_text(file)
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
            text = strip_comments(read_text(file))
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
