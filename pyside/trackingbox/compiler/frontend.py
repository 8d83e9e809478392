"""What the front end (rumoca) reads, and the flattened models kept from earlier compiles.

rumoca resolves every class of the source roots it is given: on the Modelica Standard
Library that is 10-20 s and 1.3-1.7 GB for any model, however small (measured on MSL 4.0.0:
``TwoMasses`` 11-19 s, 1.3 GB). A rumoca ``Session`` keeps that work for the next model of
the same roots (the second model flattened in 1.5-2 s) but holds 1.6 GB while it lives.
Here the front end is instead given a *front-end tree*: a temporary copy of just the files
the model can reach (:meth:`.library.LibraryIndex.frontend_files`, a superset of what
Modelica's lookup finds from the model), each as rumoca should read it (:mod:`.rewrite`: no
byte-order mark, ``der`` equations in for-loops protected), under the same relative paths
(so messages name the user's files after :meth:`FrontendTree.rename`). The same
``TwoMasses`` flattens from its 26 files in 0.6 s and 120 MB. rumoca's own cache of parsed
files (on disk, keyed by their content) makes parsing a library a once-per-change cost.

A class the index does not see (a name it could not read) makes the front end report an
unresolved name, never a different class: :func:`may_be_pruned` recognises such a failure and
the compile is repeated on the whole libraries.

The flattened model of a tree is kept on disk (:class:`FlatCache`, under
:func:`.library.cache_dir`), keyed by rumoca's version, the model's name and the content of
every file of its tree: the next compile of the same model against unchanged files skips the
front end. ``TRACKINGBOX_FRONTEND_CACHE=0`` turns the cache off.
"""
from __future__ import annotations

import gzip
import hashlib
import importlib.metadata
import logging
import os
import pickle
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from .. import config
from ..errors import CompileError
from . import (component_sizes, discrete_connects, function_locals, inner_defaults, package_copies,
               package_overrides, record_constants, redeclare_components)
from .library import LibraryIndex, cache_dir, index_for, source_root
from .modifiers import ModifierCheck
from .rewrite import asserting_function_names, frontend_bytes, tuple_function_names
from .source import ModelicaSource

log = logging.getLogger(__name__)

TREE_VERSION = 3
"""Changes when what a tree holds changes (it is part of the flat cache's key)."""

CACHE_LIMIT_MB = 512
"""The flat cache is trimmed (oldest first) to this size after each store."""


def rumoca_version() -> str:
    try:
        return importlib.metadata.version("rumoca")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - rumoca is a dependency
        return "unknown"


@dataclass
class FrontendTree:
    """A copy of (a part of) the source and its libraries for the front end.

    Attributes
    ----------
    entry:
        The file rumoca loads (the model's own class file where the index knows it).
    roots:
        rumoca's source roots (the directory holding the copied packages), or None.
    renames:
        (prefix in the copy, prefix of the original) pairs, longest first.
    originals:
        Copied file -> the user's file.
    digest:
        Hash of every copied file's relative path and content.
    pruned:
        Whether only the files the model can reach were copied.
    """

    entry: Path
    roots: list[Path] | None
    renames: list[tuple[str, str]]
    originals: dict[Path, Path] = field(default_factory=dict)
    digest: str = ""
    pruned: bool = False
    entry_rel: str = ""

    def rename(self, obj: object) -> object:
        """*obj* (a worker's answer: messages, diagnostics) with the copy's paths replaced by the user's."""
        if isinstance(obj, dict):
            return {k: (v if k == "flat" else self.rename(v)) for k, v in obj.items()}
        if isinstance(obj, (list, tuple)):
            return type(obj)(self.rename(v) for v in obj)
        if isinstance(obj, str):
            for old, new in self.renames:
                obj = obj.replace(old, new)
            return obj
        return obj

    def copy_of(self, original: Path) -> Path | None:
        for copy, orig in self.originals.items():
            if orig == original:
                return copy
        return None

    def cache_key(self, model: str) -> str:
        text = "|".join((rumoca_version(), str(TREE_VERSION), model, self.entry_rel, self.digest))
        return hashlib.sha256(text.encode()).hexdigest()


def build_tree(source: ModelicaSource, model: str, libraries: tuple[Path, ...], dest: Path,
               prune: bool = True, index: LibraryIndex | None = None, computed: bool = False,
               inner_values: dict[str, str] | None = None, undefined: frozenset[str] = frozenset()) -> FrontendTree:
    """Copy what the front end needs for *model* under *dest* (see the module docstring).

    With *prune*, the files the model can reach, from the source and the libraries, under
    ``dest/lib/<package>/...`` (rumoca's root; the entry is the model's own file); a single-file
    source goes to ``dest/src``. Without, the whole source as the compiler always gave it
    (``dest/src/...`` relative to the source's root directory, entry its ``package.mo`` or file,
    the libraries as they are). With *computed* (a retry after rumoca counted an assert as an
    equation), parameters bound to a call of a function that asserts are computed at
    initialisation (:func:`.rewrite.computed_parameter_bindings`). *inner_values*: the values of
    inner modifications that name other parameters, read from a first flat model
    (:func:`.inner_defaults.flat_values`). *undefined*: functions whose locals assigned on some
    branches only get an undefined binding (:mod:`.function_locals`; a retry after rumoca refused one).
    """
    index = index if index is not None else index_for(source, libraries)
    reached = index.frontend_files(model) if model in index.classes else None
    inner = inner_defaults.patches(index, model, reached, inner_values) if reached else {}  # outer references
    inner = _chained(inner, discrete_connects.patches(index, model) if reached else {})
    repeated = package_overrides.patches(ModifierCheck(index), model) if reached else {}  # (values rumoca loses)
    inner = _chained(inner, repeated)
    inner = _chained(inner, record_constants.patches(index, model) if reached else {})  # (fields rumoca misses)
    inner = _chained(inner, component_sizes.patches(index, model) if reached else {})  # (arrays rumoca mis-sizes)
    inner = _chained(inner, redeclare_components.patches(index, model) if reached else {})  # (modifications lost)
    inner = _chained(inner, function_locals.patches(index, undefined) if undefined else {})  # (locals rumoca refuses)
    needed = reached if prune else None
    if needed is None:
        return _full_tree(source, libraries, dest, inner)
    lib_dir, src_dir = dest / "lib", dest / "src"
    tuple_names = tuple_function_names(sorted(needed))
    asserting = asserting_function_names(sorted(needed)) if computed else frozenset()

    def read(f: Path, patched=dict(inner)) -> bytes:  # a file as the front end reads it
        data = frontend_bytes(f, tuple_names, asserting)
        data = f.read_bytes() if data is None else data
        return patched[f](data) if f in patched else data
    inner = _chained(inner, package_copies.patches(index, model, read))  # (modified packages' functions lost)
    digest = hashlib.sha256()
    originals: dict[Path, Path] = {}
    renames: list[tuple[str, str]] = []
    taken: set[str] = set()
    own = source_root(source)
    for root in (own, *libraries):
        root = Path(root)
        if root.name in taken:  # the same top-level name twice: the first one counts (as in the index)
            continue
        taken.add(root.name)
        if root.is_dir():
            files = [f for f in sorted(root.rglob("*.mo")) if f in needed]
            base = lib_dir / root.name
            renames.append((str(base) + os.sep, str(root) + os.sep))
            for f in files:
                target = base / f.relative_to(root)
                _copy(f, target, digest, f"{root.name}/{f.relative_to(root)}", tuple_names, asserting,
                      inner.get(f))
                originals[target] = f
        else:
            target = (src_dir if root == own else lib_dir) / root.name
            _copy(root, target, digest, root.name, tuple_names, asserting, inner.get(root))
            originals[target] = root
            renames.append((str(target), str(root)))
    if source.entry.name != "package.mo":
        entry = src_dir / source.entry.name
    else:
        wanted = index.classes[model].file
        entry = next((c for c, o in originals.items() if o == wanted), None) or \
            next(c for c, o in originals.items() if o == source.entry)
    renames.sort(key=lambda r: -len(r[0]))
    roots = [lib_dir] if lib_dir.is_dir() else None
    return FrontendTree(entry=entry, roots=roots, renames=renames, originals=originals,
                        digest=digest.hexdigest(), pruned=True, entry_rel=str(entry.relative_to(dest)))


def _chained(first: dict, then: dict) -> dict:
    """Per-file patches of *first* followed by those of *then* for the same file."""
    out = dict(first)
    for f, patch in then.items():
        before = out.get(f)
        out[f] = patch if before is None else (lambda body, a=before, b=patch: b(a(body)))
    return out


def _full_tree(source: ModelicaSource, libraries: tuple[Path, ...], dest: Path, inner=None) -> FrontendTree:
    """The whole source as rumoca should read it, the libraries as they are (the compiler's
    behaviour before front-end trees, kept for what the index cannot place)."""
    digest = hashlib.sha256()
    copy_root = dest / "src"
    originals: dict[Path, Path] = {}
    tuple_names = tuple_function_names(source.files)
    outside = sorted(set(inner or {}) - set(source.files))
    if outside:  # the libraries are read as they are: an edit that keeps a value right would be lost
        raise CompileError(f"the front end must read {outside[0]} edited for {source.entry} (a value rumoca "
                           "0.10.2 reads wrong), which the whole-library reading cannot do")
    for f in source.files:
        target = copy_root / f.relative_to(source.root)
        _copy(f, target, digest, str(f.relative_to(source.root)), tuple_names, patch=(inner or {}).get(f))
        originals[target] = f
    for lib in libraries:  # not copied: their content enters the key by their files' stamps
        for f in (sorted(Path(lib).rglob("*.mo")) if Path(lib).is_dir() else [Path(lib)]):
            try:
                st = f.stat()
            except OSError:
                continue
            digest.update(f"{f}|{st.st_size}|{st.st_mtime_ns}".encode())
    entry = copy_root / source.entry.relative_to(source.root)
    roots = [copy_root, *(Path(p) for p in libraries)] if libraries else None
    return FrontendTree(entry=entry, roots=roots, renames=[(str(copy_root), str(source.root))],
                        originals=originals, digest=digest.hexdigest(), pruned=False,
                        entry_rel=str(entry.relative_to(dest)))


def _copy(src: Path, target: Path, digest, rel: str, tuple_names: frozenset[bytes] = frozenset(),
          asserting: frozenset[bytes] = frozenset(), patch=None) -> None:
    data = frontend_bytes(src, tuple_names, asserting)
    if data is None:
        data = src.read_bytes()
    if patch is not None:
        data = patch(data)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_bytes(data)
    digest.update(rel.encode() + b"\0" + hashlib.sha256(data).digest())


_QUOTED = re.compile(r"'([A-Za-z_][\w.]*)'|`([A-Za-z_][\w.]*)`")
_PRUNING_SIGNS = ("unresolved", "not found", "undefined", "unknown", "no class", "cannot find")


def may_be_pruned(message: str, index: LibraryIndex, tree: FrontendTree) -> bool:
    """Whether a front-end failure on a pruned *tree* may come from a file left out: the message says
    a name was not found, and a class of that name (any part of it) is in a file the tree lacks."""
    low = message.lower()
    if not any(sign in low for sign in _PRUNING_SIGNS):
        return False
    copied = set(tree.originals.values())
    for m in _QUOTED.finditer(message):
        quoted = m.group(1) or m.group(2)
        found = index.lookup_global(quoted) if "." in quoted else None
        if found is not None:  # a full name: its class was copied or not
            if index.classes[found].file not in copied:
                return True
            continue
        for part in quoted.split("."):
            for name in index.by_simple.get(part, ()):
                if index.classes[name].file not in copied:
                    return True
    return False


class FlatCache:
    """Flattened models on disk, keyed by :meth:`FrontendTree.cache_key`."""

    def __init__(self, root: Path | None = None):
        self.root = (root or cache_dir()) / "flat"

    @staticmethod
    def enabled() -> bool:
        return bool(config.get("frontend_cache"))

    def path(self, key: str) -> Path:
        return self.root / key[:2] / f"{key}.pickle.gz"

    def get(self, key: str) -> dict | None:
        path = self.path(key)
        try:
            with gzip.open(path, "rb") as fh:
                flat = pickle.load(fh)
        except FileNotFoundError:
            return None
        except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ValueError) as exc:
            log.debug("flat cache entry %s unreadable (%s): ignored", path, exc)
            return None
        try:
            os.utime(path)
        except OSError:
            pass
        return flat if isinstance(flat, dict) else None

    def put(self, key: str, flat: dict) -> None:
        path = self.path(key)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            part = path.with_name(f".{path.name}.{os.getpid()}.part")
            with gzip.open(part, "wb", compresslevel=3) as fh:
                pickle.dump(flat, fh, protocol=pickle.HIGHEST_PROTOCOL)
            os.replace(part, path)
            self.trim()
        except (OSError, pickle.PicklingError, RecursionError) as exc:  # a cache that cannot be written is only slower
            log.debug("flat model not cached at %s: %s", path, exc)

    def trim(self, limit_mb: float = CACHE_LIMIT_MB) -> None:
        entries = []
        for p in self.root.glob("*/*.pickle.gz"):
            try:
                st = p.stat()
            except OSError:
                continue
            entries.append((st.st_mtime, st.st_size, p))
        total = sum(e[1] for e in entries)
        for _, size, p in sorted(entries):
            if total <= limit_mb * 1024 * 1024:
                break
            try:
                p.unlink()
                total -= size
            except OSError:
                pass

    def clear(self) -> None:
        shutil.rmtree(self.root, ignore_errors=True)


__all__ = ["FlatCache", "FrontendTree", "build_tree", "may_be_pruned", "rumoca_version"]
