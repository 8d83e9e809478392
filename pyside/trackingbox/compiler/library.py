"""An index of the classes of Modelica source trees, and name lookup in a model's scope.

Every ``.mo`` file of the source and of the libraries it uses is read once: each
class definition gets its full name, kind, file, character and line span, the
names its own text refers to (its nested classes are classes of their own), its
``extends`` clauses and imports. The index of a file is kept on disk (see
:func:`cache_dir`) under the file's size and modification time, so a library as
large as the Modelica Standard Library (2500 files, 27 MB) is read once per
change, not once per compile.

On the index:

* :meth:`LibraryIndex.lookup` resolves a name the way Modelica does (MLS 5.3): from the
  class that uses it outwards through the enclosing classes (their nested classes,
  inherited ones included, and their imports) to the top-level packages, stopping at
  the first class that has it;
* :meth:`LibraryIndex.used_classes` is the set of classes a model uses: its own class,
  and every class a name in a used class resolves to (``extends``, component types,
  functions, packages of constants), followed transitively. The compiler's checks and
  the search for a construct's line look only there, never at a class elsewhere in a
  library that merely shares a name;
* :meth:`LibraryIndex.frontend_files` is a superset of the files a model needs, safe to
  give the front end instead of whole libraries (see its docstring).
"""
from __future__ import annotations

import bisect
import contextlib
import contextvars
import hashlib
import logging
import os
import pickle
import re
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from .. import config
from .source import Location, ModelicaSource, _code, blanked, strip_comments

log = logging.getLogger(__name__)

INDEX_VERSION = 3
"""Changes whenever what the index records changes (old cache entries are then ignored)."""

_KINDS = ("model", "block", "class", "connector", "record", "package", "function", "type", "operator")
_PREFIXES = ("partial", "encapsulated", "final", "replaceable", "redeclare", "expandable", "pure", "impure",
             "inner", "outer", "operator")
_HEAD = re.compile(
    r"(?<![\w.])((?:(?:partial|encapsulated|final|replaceable|redeclare|expandable|pure|impure|inner|outer)\s+)*)"
    r"(?:(expandable)\s+)?(operator\s+(?:record|function)|model|block|class|connector|record|package|function|type"
    r"|operator)\s+(extends\s+)?([A-Za-z_]\w*)")
_END = re.compile(r"(?<![\w.])end\s+([A-Za-z_]\w*)\s*;")
_WITHIN = re.compile(r"^\s*within\s*([\w.]*)\s*;")
_NAME = re.compile(r"(?<![\w.\]])\.?([A-Za-z_]\w*(?:\s*\.\s*[A-Za-z_]\w*)*)")
_EXTENDS = re.compile(r"(?<![\w.])extends\s+(\.?[A-Za-z_][\w.]*)")
_IMPORT = re.compile(r"(?<![\w.])import\s+(?:([A-Za-z_]\w*)\s*=\s*)?(\.?[A-Za-z_][\w.]*?)(\.\*|\.\{[^}]*\})?\s*;")
_ANNOTATION = re.compile(r"(?<![\w.])annotation\s*\(")
_DERIVATIVE = re.compile(r"\b(?:derivative|inverse)\b[^=;]*?=\s*([A-Za-z_][\w.]*)")
_EXPERIMENT = re.compile(r"(?<![\w.])experiment\s*\(")
_SHORT_BASE = re.compile(r"\s*=\s*(?:(?:input|output|flow|stream|discrete|parameter|constant)\s+)*"
                         r"(\.?[A-Za-z_][\w.]*)")
_WORD = re.compile(r"[A-Za-z_]\w*")

BUILTIN_CLASSES = frozenset({
    "Real", "Integer", "Boolean", "String", "StateSelect", "AssertionLevel", "Connections", "ExternalObject",
    "Clock", "Subtask", "ModelicaServicesDummy",
})
"""Predefined classes and enumerations of the language (MLS 4.9, 8.3.7, 9.4, 16): never a library."""

KEYWORDS = frozenset({
    "algorithm", "and", "annotation", "block", "break", "class", "connect", "connector", "constant",
    "constrainedby", "der", "discrete", "each", "else", "elseif", "elsewhen", "encapsulated", "end",
    "enumeration", "equation", "expandable", "extends", "external", "false", "final", "flow", "for",
    "function", "if", "import", "impure", "in", "initial", "inner", "input", "loop", "model", "not",
    "operator", "or", "outer", "output", "package", "parameter", "partial", "protected", "public", "pure",
    "record", "redeclare", "replaceable", "return", "stream", "then", "true", "type", "when", "while",
    "within", "time",
})


@dataclass
class ClassInfo:
    """One class definition.

    ``start``/``end`` are character offsets in the comment-free text of ``file`` (the same offsets as
    in the file's text: comments and strings are blanked, not removed); ``line``/``last_line`` the
    first and last line. ``names`` are the (dotted) names the class's own text refers to, without its
    nested classes and without annotations (except ``derivative``/``inverse`` functions).
    """

    name: str
    kind: str
    file: Path
    start: int
    end: int
    line: int
    last_line: int
    partial: bool = False
    short: bool = False
    encapsulated: bool = False
    redeclared: bool = False  # a `redeclare` element (or a class extends) of an enclosing class
    class_extends: bool = False  # `model extends M` (redefines the inherited M)
    names: tuple[str, ...] = ()
    extends: tuple[str, ...] = ()
    imports: tuple[tuple[str, str, str], ...] = ()  # (alias or "", target, "" | "*" | "{...}")
    experiment: bool = False

    @property
    def simple(self) -> str:
        return self.name.rsplit(".", 1)[-1]

    @property
    def parent(self) -> str | None:
        return self.name.rsplit(".", 1)[0] if "." in self.name else None


def _paren_end(code: str, pos: int) -> int:
    """Position after the parenthesis that closes the one at *pos*."""
    depth = 0
    for m in re.compile(r"[()]").finditer(code, pos):
        depth += 1 if m.group(0) == "(" else -1
        if depth == 0:
            return m.end()
    return len(code)


def _expected_prefix(file: Path, root: Path | None) -> str:
    """The enclosing package a file's position in a package tree implies (``A/B/C.mo`` -> ``A.B``)."""
    if root is None:
        return ""
    try:
        rel = file.relative_to(root)
    except ValueError:
        return ""
    parts = list(rel.with_suffix("").parts)
    if parts and parts[-1] == "package":
        parts = parts[:-1]
    return ".".join(parts[:-1])


def scan_file(file: Path, code: str, root: Path | None = None) -> list[ClassInfo]:
    """The class definitions of one file's comment-free *code*.

    Full names come from the file's ``within`` clause (else from its place under *root*) and the
    nesting of the definitions. Class heads inside parentheses (``redeclare model M = ...`` in a
    modification, partial applications ``function f(x = 1)``) are not members and are skipped.
    """
    within = _WITHIN.search(code)
    prefix = within.group(1) if within else _expected_prefix(file, root)
    newlines = [m.start() for m in re.finditer("\n", code)]

    def line_of(pos: int) -> int:
        return bisect.bisect_right(newlines, pos - 1) + 1

    # depth of parentheses at each class head (heads inside modifications are not members)
    parens = [(m.start(), 1 if m.group(0) == "(" else -1) for m in re.finditer(r"[()]", code)]
    heads = []
    for m in _HEAD.finditer(code):
        heads.append(m)
    events: list[tuple[int, int, object]] = [(m.start(), 0, m) for m in heads]
    events += [(m.start(), 1, m) for m in _END.finditer(code)]
    events.sort(key=lambda e: (e[0], e[1]))
    # walk heads, ends and parentheses together
    depth = 0
    pi = 0
    stack: list[dict] = []
    found: list[dict] = []
    for pos, kind, m in events:
        while pi < len(parens) and parens[pi][0] < pos:
            depth += parens[pi][1]
            pi += 1
        if kind == 0:
            prefixes = m.group(1) or ""
            word = m.group(3)
            name = m.group(5)
            after = code[m.end():m.end() + 400]
            stripped = after.lstrip()
            if depth > (stack[-1]["depth"] if stack else 0) or "(" == stripped[:1] and word == "function":
                continue  # inside a modification, or a partial application function f(...)
            if name in KEYWORDS and name not in ("initial",):
                continue
            entry = {
                "simple": name, "kind": " ".join(word.split()),
                "start": m.start(), "head_end": m.end(), "depth": depth,
                "partial": "partial" in prefixes.split(), "encapsulated": "encapsulated" in prefixes.split(),
                "redeclared": "redeclare" in prefixes.split() or bool(m.group(4)),
                "class_extends": bool(m.group(4)), "children": [],
            }
            if stripped.startswith("="):  # short class definition: ends at the semicolon
                semi = code.find(";", m.end())
                entry["end"] = len(code) if semi < 0 else semi + 1
                entry["short"] = True
                base = _SHORT_BASE.match(after)
                entry["base"] = base.group(1) if base and not after.lstrip()[1:].lstrip().startswith(
                    ("enumeration", "der(", "der (")) else None
                entry["path"] = [s["simple"] for s in stack] + [name]
                found.append(entry)
                if stack:
                    stack[-1]["children"].append(entry)
                continue
            entry["short"] = False
            entry["path"] = [s["simple"] for s in stack] + [name]
            if stack:
                stack[-1]["children"].append(entry)
            stack.append(entry)
            found.append(entry)
        else:
            name = m.group(1)
            names = [s["simple"] for s in stack]
            if name not in names:
                continue  # end if; end for; end when; ...
            k = len(names) - 1 - names[::-1].index(name)
            for s in stack[k:]:
                s["end"] = m.end()
            del stack[k:]
    for s in stack:
        s["end"] = len(code)
    out: list[ClassInfo] = []
    for e in found:
        full = ".".join(p for p in (prefix, *e["path"]) if p)
        body_start, body_end = e["head_end"], e["end"]
        own = _own_text(code, body_start, body_end, e["children"])
        names, experiment = _names(own)
        if e["short"]:
            extends = (e["base"],) if e.get("base") else ()
            imports: tuple = ()
        else:
            extends = tuple(x.group(1).lstrip(".") for x in _EXTENDS.finditer(own))
            imports = tuple((x.group(1) or "", x.group(2).lstrip("."), (x.group(3) or "").lstrip("."))
                            for x in _IMPORT.finditer(own))
        out.append(ClassInfo(
            name=full, kind=e["kind"], file=file, start=e["start"], end=e["end"], line=line_of(e["start"]),
            last_line=line_of(max(e["start"], e["end"] - 1)), partial=e["partial"], short=e["short"],
            encapsulated=e["encapsulated"], redeclared=e["redeclared"], class_extends=e["class_extends"],
            names=names, extends=extends, imports=imports, experiment=experiment,
        ))
    return out


def _own_text(code: str, start: int, end: int, children: list[dict]) -> str:
    """The text of a class between *start* and *end* with its nested classes blanked."""
    if not children:
        return code[start:end]
    parts = []
    pos = start
    for c in sorted(children, key=lambda c: c["start"]):
        if c["start"] < pos:
            continue
        parts.append(code[pos:c["start"]])
        parts.append(" ")
        pos = c["end"]
    parts.append(code[pos:end])
    return "".join(parts)


def _names(text: str) -> tuple[tuple[str, ...], bool]:
    """The dotted names *text* refers to, annotations left out (their derivative and inverse
    functions kept), and whether an annotation holds ``experiment(...)``."""
    kept = []
    extra: list[str] = []
    experiment = False
    pos = 0
    for m in _ANNOTATION.finditer(text):
        if m.start() < pos:
            continue
        close = _paren_end(text, m.end() - 1)
        ann = text[m.end():close]
        if _EXPERIMENT.search(ann):
            experiment = True
        extra += [d.group(1) for d in _DERIVATIVE.finditer(ann)]
        kept.append(text[pos:m.start()])
        pos = close
    kept.append(text[pos:])
    body = " ".join(kept)
    names = dict.fromkeys(extra)
    for m in _NAME.finditer(body):
        name = re.sub(r"\s+", "", m.group(1))
        first = name.split(".", 1)[0]
        if first in KEYWORDS:
            continue
        names[name] = None
    return tuple(names), experiment


# ----------------------------------------------------------------------------------- disk cache
def cache_dir() -> Path:
    """Where trackingbox keeps what it computed from Modelica sources (the class index, flattened
    models): ``$TRACKINGBOX_CACHE_DIR``, else ``$XDG_CACHE_HOME/trackingbox`` (``~/.cache/trackingbox``)."""
    env = config.get("cache_dir")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "trackingbox"


def _file_key(file: Path, st: os.stat_result, root: Path | None) -> str:
    return f"{INDEX_VERSION}|{file}|{st.st_size}|{st.st_mtime_ns}|{root}"


_MEMORY: dict[str, list[ClassInfo]] = {}
_LOCK = threading.Lock()


def _tree_cache_path(root: Path) -> Path:
    digest = hashlib.sha256(f"{INDEX_VERSION}|{root}".encode()).hexdigest()[:24]
    return cache_dir() / "index" / f"{digest}.pickle"


def index_tree(root: Path, files: list[Path] | None = None) -> tuple[list[ClassInfo], str]:
    """The classes of every ``.mo`` file under the package directory or file *root*, and a
    fingerprint of the files read (their names, sizes and modification times).

    Per-file results are reused while a file's size and modification time are unchanged,
    in memory and on disk; a file that cannot be read is skipped.
    """
    root = Path(root)
    if files is None:
        files = sorted(root.rglob("*.mo")) if root.is_dir() else [root]
    tree_root = root.parent if root.is_dir() else None
    disk_path = _tree_cache_path(root)
    with _LOCK:
        disk: dict[str, list[ClassInfo]] | None = None
        out: list[ClassInfo] = []
        fresh: dict[str, list[ClassInfo]] = {}
        changed = False
        for file in files:
            try:
                st = file.stat()
            except OSError:
                continue
            key = _file_key(file, st, tree_root)
            classes = _MEMORY.get(key)
            if classes is None:
                if disk is None:
                    disk = _read_disk(disk_path)
                classes = disk.get(key)
                if classes is None:
                    try:
                        code = strip_comments(file.read_text(encoding="utf-8-sig", errors="replace"))
                    except OSError:
                        continue
                    classes = scan_file(file, code, tree_root)
                    changed = True
                _MEMORY[key] = classes
            fresh[key] = classes
            out.extend(classes)
        if changed or (disk is not None and set(disk) != set(fresh)):
            _write_disk(disk_path, fresh)
        return out, hashlib.sha256("\n".join(fresh).encode()).hexdigest()


def _read_disk(path: Path) -> dict[str, list[ClassInfo]]:
    try:
        with open(path, "rb") as fh:
            data = pickle.load(fh)
        return data if isinstance(data, dict) else {}
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError, TypeError, ValueError):
        return {}


def _write_disk(path: Path, data: dict[str, list[ClassInfo]]) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        part = path.with_suffix(f".{os.getpid()}.part")
        with open(part, "wb") as fh:
            pickle.dump(data, fh, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(part, path)
    except OSError as exc:  # a read-only cache is only slower
        log.debug("class index not cached at %s: %s", path, exc)


_NEWLINES: dict[Path, tuple[int, list[int]]] = {}


def line_of(file: Path, offset: int) -> int:
    """The line of the character *offset* of *file*'s (comment-free) text."""
    code = _code(file)
    cached = _NEWLINES.get(file)
    if cached is None or cached[0] != len(code):
        cached = (len(code), [m.start() for m in re.finditer("\n", code)])
        _NEWLINES[file] = cached
    return bisect.bisect_left(cached[1], offset) + 1


_INDEXES: dict[tuple[Path, ...], LibraryIndex] = {}
#: Inside :func:`one_look`: the root sets whose files were looked at (stat) once already.
_LOOKED: contextvars.ContextVar[set[tuple[Path, ...]] | None] = contextvars.ContextVar("_LOOKED", default=None)


@contextlib.contextmanager
def one_look() -> Iterator[None]:
    """Within: :func:`index_for` looks at a set of roots' files once, then takes them as unchanged.

    One compilation asks for the same index several times; without this, each request
    checks the size and modification time of every file (MSL: 2500 files). Outside, and
    in the next ``one_look``, a changed file is seen again. Nested uses share the outer one.
    """
    if _LOOKED.get() is not None:
        yield
        return
    token = _LOOKED.set(set())
    try:
        yield
    finally:
        _LOOKED.reset(token)


def index_for(source, libraries: tuple[Path, ...] | list[Path] = ()) -> LibraryIndex:
    """The index of a :class:`~.source.ModelicaSource` and the libraries it is compiled with
    (reused in this process while no file changed; within :func:`one_look`, the files are
    looked at on the first request only)."""
    roots = (source_root(source), *(Path(p) for p in libraries))
    roots = tuple(dict.fromkeys(roots))
    looked = _LOOKED.get()
    if looked is not None and roots in looked and roots in _INDEXES:
        return _INDEXES[roots]
    if looked is not None:
        looked.add(roots)
    fresh = LibraryIndex.build(roots) if roots not in _INDEXES else None
    if fresh is None:
        old = _INDEXES[roots]
        trees = [index_tree(r) for r in roots]
        if old.fingerprint == hashlib.sha256("|".join(t[1] for t in trees).encode()).hexdigest():
            return old
        fresh = LibraryIndex.build(roots, trees)
    _INDEXES[roots] = fresh
    return fresh


def source_root(source) -> Path:
    """The package directory of a package source, or the file of a single-file source."""
    return source.entry.parent if source.entry.name == "package.mo" else source.entry


# ----------------------------------------------------------------------------------- the index
@dataclass
class LibraryIndex:
    """The classes of a set of Modelica package trees (the source first, then its libraries)."""

    roots: tuple[Path, ...]
    classes: dict[str, ClassInfo] = field(default_factory=dict)
    children: dict[str, dict[str, str]] = field(default_factory=dict)
    by_simple: dict[str, list[str]] = field(default_factory=dict)
    duplicates: list[tuple[str, Path, Path]] = field(default_factory=list)
    fingerprint: str = ""

    @classmethod
    def build(cls, roots: tuple[Path, ...] | list[Path],
              trees: list[tuple[list[ClassInfo], str]] | None = None) -> LibraryIndex:
        """Index the package directories or ``.mo`` files *roots*; the first definition of a
        full name wins (later ones are listed in ``duplicates``). *trees*: the roots'
        :func:`index_tree` results when the caller has them already."""
        idx = cls(tuple(Path(r) for r in roots))
        prints = []
        for k, root in enumerate(idx.roots):
            classes, fingerprint = trees[k] if trees is not None else index_tree(root)
            prints.append(fingerprint)
            for c in classes:
                if c.name in idx.classes:
                    if idx.classes[c.name].file != c.file or idx.classes[c.name].start != c.start:
                        idx.duplicates.append((c.name, idx.classes[c.name].file, c.file))
                    continue
                idx.classes[c.name] = c
        for name in idx.classes:
            parent, _, simple = name.rpartition(".")
            idx.children.setdefault(parent, {})[simple] = name
            idx.by_simple.setdefault(simple, []).append(name)
        idx._members: dict[tuple[str, str], str | None] = {}
        idx._bases: dict[str, tuple[str, ...]] = {}
        idx._importing: dict[Path, list[str]] = {}  # the classes with an import clause, by file
        for name in (n for n, c in idx.classes.items() if c.imports):
            idx._importing.setdefault(idx.classes[name].file, []).append(name)
        idx.fingerprint = hashlib.sha256("|".join(prints).encode()).hexdigest()
        return idx

    # ------------------------------------------------------------------ lookup
    def top(self, name: str) -> str | None:
        """A top-level class (a library's root package, or a class of a single-file source)."""
        return name if name in self.children.get("", {}) else None

    def ancestors(self, cls: str) -> list[str]:
        """*cls* and every class it extends, directly or through its bases (each once, *cls* first)."""
        out: dict[str, None] = {}
        todo = [cls]
        while todo:
            name = todo.pop()
            if name not in out and name in self.classes:
                out[name] = None
                todo.extend(self.bases(name))
        return list(out)

    def bases(self, cls: str) -> tuple[str, ...]:
        """The classes *cls* extends (resolved), its short-class base included."""
        if cls in self._bases:
            return self._bases[cls]
        self._bases[cls] = ()  # cycle guard
        info = self.classes.get(cls)
        out: list[str] = []
        if info is not None:
            scope = info.parent or ""
            for ext in info.extends:
                # an extends clause's name is looked up in the enclosing scope (its own inherited
                # members are not searched: that would need the result being computed)
                target = self.lookup(ext, scope, local=cls) if scope else self.lookup_global(ext)
                if target is not None and target != cls:
                    out.append(target)
            if info.class_extends and info.parent:  # model extends M: the inherited M's contents
                for base in self.bases(info.parent):
                    inherited = self.member(base, info.simple)
                    if inherited is not None and inherited != cls:
                        out.append(inherited)
        self._bases[cls] = tuple(dict.fromkeys(out))
        return self._bases[cls]

    def member(self, cls: str, simple: str, _seen: frozenset[str] = frozenset()) -> str | None:
        """The class named *simple* that is a member of *cls* (declared there or inherited)."""
        key = (cls, simple)
        if key in self._members:
            return self._members[key]
        own = self.children.get(cls, {}).get(simple)
        if own is not None:
            self._members[key] = own
            return own
        if cls in _seen:
            return None
        found = None
        for base in self.bases(cls):
            found = self.member(base, simple, _seen | {cls})
            if found is not None:
                break
        self._members[key] = found
        return found

    def lookup_global(self, dotted: str) -> str | None:
        """A fully qualified name: its longest prefix that is a class."""
        parts = dotted.lstrip(".").split(".")
        cur = self.top(parts[0])
        if cur is None:
            return None
        for part in parts[1:]:
            nxt = self.member(cur, part)
            if nxt is None:
                break
            cur = nxt
        return cur

    def lookup(self, dotted: str, scope: str, *, local: str | None = None) -> str | None:
        """The class a (dotted) name used in class *scope* refers to (MLS 5.3), or None.

        The first part is looked up in *scope* and then in each enclosing class (nested
        classes, inherited ones included, and imports), then among the top-level classes; the
        other parts are members of what was found. The result is the longest prefix of the
        name that is a class (``Modelica.Constants.pi`` gives ``Modelica.Constants``).
        *local*: a class whose own nested classes, but not its inherited ones, are searched
        first (for the names in its own ``extends`` clauses).
        """
        if dotted.startswith("."):
            return self.lookup_global(dotted)
        parts = dotted.split(".")
        first = self._lookup_first(parts[0], scope, local)
        if first is None:
            return None
        cur = first
        for part in parts[1:]:
            nxt = self.member(cur, part)
            if nxt is None:
                break
            cur = nxt
        return cur

    def lookup_path(self, dotted: str, scope: str) -> list[str]:
        """Each class the lookup of *dotted* from *scope* passes through (``Medium.h`` with ``package Medium =
        MoistAir``: ``Medium``, then ``PartialMedium.h``, whose names MoistAir's classes stand in for)."""
        if dotted.startswith("."):
            return [c for c in (self.lookup_global(dotted),) if c is not None]
        parts, path = dotted.split("."), []
        cur = self._lookup_first(parts[0], scope, None)
        while cur is not None:
            path.append(cur)
            cur = self.member(cur, parts[len(path)]) if len(path) < len(parts) else None
        return path

    def _lookup_first(self, name: str, scope: str, local: str | None) -> str | None:
        if local is not None:
            own = self.children.get(local, {}).get(name)
            if own is not None:
                return own
        cur: str | None = scope
        while cur:
            found = self.member(cur, name) if cur != local else self.children.get(cur, {}).get(name)
            if found is not None:
                return found
            info = self.classes.get(cur)
            if info is not None:
                for alias, target, tail in info.imports:
                    if alias == name or (not alias and not tail and target.rsplit(".", 1)[-1] == name):
                        return self.lookup_global(target)
                    if tail == "*" or (tail.startswith("{") and re.search(rf"\b{re.escape(name)}\b", tail)):
                        pkg = self.lookup_global(target)
                        if pkg is not None:
                            hit = self.member(pkg, name)
                            if hit is not None:
                                return hit
                if info.encapsulated:
                    break
            cur = cur.rsplit(".", 1)[0] if "." in cur else None
        return self.top(name)

    # ------------------------------------------------------------------ closures
    def used_classes(self, model: str) -> list[str]:
        """The classes *model* uses, in the order found: the model's class first, then every class a
        name in a used class resolves to, its bases and its enclosing class, followed transitively."""
        if model not in self.classes:
            return []
        order = [model]
        seen = {model}
        k = 0
        while k < len(order):
            cls = order[k]
            k += 1
            info = self.classes[cls]
            targets = list(self.bases(cls))
            for name in info.names:
                targets.extend(self.lookup_path(name, cls))
            # the enclosing packages: their constants and imports are in scope (a name such as `k`
            # in Heat.Capacity may be the constant Heat.k, whose binding uses other classes)
            parent = info.parent
            if parent is not None and parent in self.classes:
                targets.append(parent)
            for target in targets:
                if target not in seen:
                    seen.add(target)
                    order.append(target)
        return order

    def frontend_files(self, model: str) -> set[Path]:
        """Files enough for the front end to flatten *model*: a superset of what Modelica's lookup can
        reach from it.

        A class is taken when any taken class refers to its simple name (as any part of a dotted
        name) and its enclosing class is taken (top-level classes: when referred to); the enclosing
        classes of a taken class are taken. So every class that a lookup from a taken class could
        find under a name it uses is taken (an inner class that shadows an outer one of the same
        name is never left out), whatever inheritance or imports do. Files: those of the taken
        classes. A class the front end then misses (a name this index does not see) shows as an
        unresolved name, never as a different class.
        """
        if model not in self.classes:
            return set()
        taken: set[str] = set()
        referenced: set[str] = set()
        queue: list[str] = []

        def take(name: str) -> None:
            while name and name not in taken:
                if name not in self.classes:
                    return
                taken.add(name)
                queue.append(name)
                for simple, child in self.children.get(name, {}).items():
                    if simple in referenced:
                        take(child)
                name = name.rsplit(".", 1)[0] if "." in name else ""

        take(model)
        files_seen: set[Path] = set()
        while queue:
            info = self.classes[queue.pop()]
            if info.file not in files_seen:  # the front end resolves the imports of every class of a file it
                files_seen.add(info.file)  # reads, used or not (MoistAir.dynamicViscosity's Math.Polynomials)
                for target in (t for c in self._importing.get(info.file, ()) for _, t, _ in self.classes[c].imports):
                    if (found := self.lookup_global(target)) is not None:
                        take(found)
            new: list[str] = []
            for dotted in (*info.names, *info.extends, *(t for _, t, _ in info.imports)):
                for part in dotted.split("."):
                    if part and part not in referenced:
                        referenced.add(part)
                        new.append(part)
            for tail in (t for _, _, t in info.imports if t.startswith("{")):
                for part in _WORD.findall(tail):
                    if part not in referenced:
                        referenced.add(part)
                        new.append(part)
            for simple in new:
                for name in self.by_simple.get(simple, ()):
                    parent = name.rsplit(".", 1)[0] if "." in name else ""
                    if not parent or parent in taken:
                        take(name)
        return {self.classes[n].file for n in taken}

    def unresolved_top(self, model: str) -> dict[str, str]:  # noqa: C901
        """First parts of names used in the classes of *model* that look like library packages
        (``Modelica.Blocks...``: a dotted name whose first part resolves nowhere) but are not
        among the indexed top-level classes: name -> where it is used (``file:line`` of the class)."""
        missing: dict[str, str] = {}
        for cls in self.used_classes(model):
            info = self.classes[cls]
            for name in info.names:
                if "." not in name:
                    continue
                first = name.split(".", 1)[0]
                if first in missing or not first[:1].isupper() or first in BUILTIN_CLASSES:
                    continue
                if self.lookup(first, cls) is None and not self._is_component(first, cls):
                    use = re.search(rf"(?<![\w.]){re.escape(first)}\s*\.", self.own_code(info, annotations=False))
                    line = line_of(info.file, info.start + use.start()) if use else info.line
                    missing[first] = f"{info.name} (at {info.file}:{line})"
        return missing

    def _is_component(self, name: str, cls: str) -> bool:
        """Whether *name* is declared as a component (or a loop variable) in *cls*, an enclosing
        class or one of their bases: a rough textual test, used only before naming a library missing."""
        pattern = re.compile(
            r"(?<![\w.])(?!(?:model|block|class|connector|record|package|function|type|end|within|extends|import|"
            r"partial|encapsulated|operator|expandable|equation|algorithm)\b)[A-Za-z_][\w.]*\s*(?:\[[^\]]*\]\s*)?"
            rf"\s+{re.escape(name)}\s*(?:[\[(=;,\"]|\bif\b|\bannotation\b)|\bfor\s+{re.escape(name)}\b")
        cur: str | None = cls
        while cur:
            for c in (cur, *self.bases(cur)):
                info = self.classes.get(c)
                if info is not None and pattern.search(self.code(info)):
                    return True
            cur = cur.rsplit(".", 1)[0] if "." in cur else None
        return False

    # ------------------------------------------------------------------ text
    def code(self, info: ClassInfo) -> str:
        """The comment-free text of a class definition."""
        return _code(info.file)[info.start:info.end]

    def own_code(self, info: ClassInfo, *, annotations: bool = True) -> str:
        """The comment-free text of a class definition with its nested classes (and, unless
        *annotations*, the contents of its annotations) blanked: offsets and lines are kept."""
        text = self.code(info)
        spans = []
        for child in self.children.get(info.name, {}).values():
            c = self.classes[child]
            if c.file == info.file and info.start < c.start and c.end <= info.end:
                spans.append((c.start - info.start, c.end - info.start))
        if not annotations:
            for m in _ANNOTATION.finditer(text):
                spans.append((m.end(), _paren_end(text, m.end() - 1) - 1))
        parts: list[str] = []
        pos = 0
        for s, e in sorted(spans):  # (one pass: a package of many nested classes was quadratic)
            s = max(s, pos)
            if e <= s:
                continue
            parts.append(text[pos:s])
            parts.append(blanked(text[s:e]))
            pos = e
        parts.append(text[pos:])
        return "".join(parts)

    def location(self, info: ClassInfo, offset: int) -> tuple[Path, int]:
        """File and line of the character *offset* of the text of class *info*."""
        return info.file, line_of(info.file, info.start + offset)

    def examples(self, package: str) -> list[str]:
        """Classes under *package* (itself included) that can be simulated as they stand: models and
        blocks, not partial, with an ``experiment`` annotation."""
        prefix = package + "."
        return sorted(n for n, c in self.classes.items()
                      if (n == package or n.startswith(prefix)) and c.experiment and not c.partial
                      and c.kind in ("model", "block", "class"))


# ----------------------------------------------------------------------------------- libraries
def library_candidates(paths: list[Path] | tuple[Path, ...]) -> dict[str, Path]:
    """Top-level packages a directory of libraries offers (a MODELICAPATH entry, or the directory
    beside a package): ``Name/package.mo``, ``Name.mo``, or versioned ``Name 4.0.0/package.mo``;
    the first of each name wins."""
    found: dict[str, Path] = {}
    for directory in paths:
        directory = Path(directory)
        try:
            entries = sorted(directory.iterdir())
        except OSError:
            continue
        for p in entries:
            name = p.stem if p.suffix == ".mo" else p.name
            name = name.split(" ", 1)[0]
            if not re.fullmatch(r"[A-Za-z_]\w*", name) or name in found:
                continue
            if (p.is_dir() and (p / "package.mo").is_file()) or (p.is_file() and p.suffix == ".mo"):
                found[name] = p
    return found


def modelicapath() -> list[Path]:
    """The directories of ``$MODELICAPATH`` (separated by the platform's path separator)."""
    raw = os.environ.get("MODELICAPATH", "")
    return [Path(p).expanduser() for p in raw.split(os.pathsep) if p.strip()]


def normalize_libraries(libraries) -> list[Path]:
    """``--library`` arguments as package roots: a package directory or ``.mo`` file as it is; a
    directory of packages (a MODELICAPATH-like directory, e.g. the one holding ``Modelica``) as each
    of its packages. A path that is neither is a :class:`~trackingbox.errors.CompileError`."""
    from ..errors import CompileError

    out: list[Path] = []
    for lib in libraries:
        path = Path(lib).expanduser()
        if not path.exists():
            raise CompileError(f"library {str(lib)!r} does not exist")
        path = path.resolve()
        if (path.is_dir() and (path / "package.mo").is_file()) or (path.is_file() and path.suffix == ".mo"):
            out.append(path)
            continue
        if path.is_dir():
            offered = library_candidates([path])
            if offered:
                out.extend(offered.values())
                continue
        raise CompileError(f"library {str(lib)!r} is not a Modelica package (a directory with package.mo, or "
                           "a .mo file) nor a directory of packages")
    return list(dict.fromkeys(out))


def resolve_libraries(source, model: str, libraries=()) -> tuple[tuple[Path, ...], dict[str, str]]:
    """The libraries *model* needs: the given ones, then, for each top-level package the model's
    classes use but none of those holds, the package of that name beside the source's package or
    beside a given library, else on ``MODELICAPATH``. Returns the libraries and the packages still
    not found (name -> the class that uses it and where)."""
    libs = normalize_libraries(libraries)
    own = source_root(source)
    beside = [p.parent for p in (own, *libs)]
    places = list(dict.fromkeys([*beside, *modelicapath()]))
    offered = library_candidates(places)
    missing: dict[str, str] = {}
    for _ in range(20):  # each round may add a library that uses another
        index = index_for(source, libs)
        missing = index.unresolved_top(model) if model in index.classes else {}
        added = [offered[n] for n in missing if n in offered and offered[n] not in libs and offered[n] != own]
        if not added:
            break
        log.info("libraries found for %s: %s", model, ", ".join(str(p) for p in added))
        libs.extend(added)
    return tuple(libs), missing


__all__ = ["ClassInfo", "LibraryIndex", "cache_dir", "index_tree", "library_candidates", "modelicapath",
           "normalize_libraries", "resolve_libraries", "scan_file"]


def locate(source: ModelicaSource, model: str, pattern: str, limit: int = 5, *,
           own: bool = False, libraries: tuple[Path, ...] | list[Path] = ()) -> list[Location]:
    """Where the regular expression *pattern* matches in the code of *model* and the classes it uses.

    Only the text of the model's own class and of the classes it uses (in the order Modelica's
    lookup finds them, :meth:`.library.LibraryIndex.used_classes`) is searched, each class's own
    text without its nested classes, so an occurrence elsewhere in the package or in a library is
    never named, and a large library file is never searched as a whole. With *own*, only the
    model's own class definition (its nested classes included) is searched.
    """
    regex = re.compile(pattern)
    index = index_for(source, libraries)
    info = index.classes.get(model)
    if info is None:
        return []
    found: list[Location] = []
    if own:
        text = index.code(info)
        for match in regex.finditer(text):
            found.append(Location(*index.location(info, match.start())))
            if len(found) >= limit:
                break
        return found
    for name in index.used_classes(model):
        cls = index.classes[name]
        text = index.own_code(cls) if name != model else index.code(cls)
        for match in regex.finditer(text):
            loc = Location(*index.location(cls, match.start()))
            if loc not in found:
                found.append(loc)
            if len(found) >= limit:
                return found
    return found


def model_files(source: ModelicaSource, model: str, limit: int = 40,
                libraries: tuple[Path, ...] | list[Path] = ()) -> tuple[Path, ...]:
    """The files of the classes *model* uses: its own class file first, then the files of the
    classes it uses (extends, component types, functions, packages of constants), followed
    transitively, as Modelica's lookup resolves their names in the model's scope
    (:meth:`.library.LibraryIndex.used_classes`); at most *limit* files."""
    index = index_for(source, libraries)
    found: list[Path] = []
    for name in index.used_classes(model):
        file = index.classes[name].file
        if file not in found:
            found.append(file)
            if len(found) >= limit:
                break
    return tuple(found)
