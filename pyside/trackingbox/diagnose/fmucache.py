"""Compiled patched twins kept between diagnoses, under the content of everything that decides them.

A ``compile`` entry is screened through its patched twin, compiled once per entry and target
(:func:`trackingbox.diagnose.fit.prepare`), and the same FMU serves the proper fit in the same work
folder. Between diagnoses (the next case of a suite on the same bench, another noise level or
seed, a rerun) the patches are the same text on the same twin, and were compiled again: on the
single-effect evaporator 14 compiles of 2.7 s, on the 3-effect train 38 of 4-5 s. Here the FMU
is kept under :func:`trackingbox.compiler.library.cache_dir` ``/patches``, keyed by a hash of

* the patch rendered at the entry's own starts (its parameters are tunable, so their values do
  not change the FMU) and the twin's Modelica source (``[source]``: every ``.mo`` file of its
  folder), as the work folder's own marker (:func:`trackingbox.diagnose.fit._compile_key`);
* every ``.mo`` file of the shipped TrackingBox library and of the spec's ``[source] libraries``;
* the compiler: trackingbox's version, the source of its ``trackingbox.compiler`` package, the
  versions of rumoca, CasADi and FMPy (its C headers), and the C compiler named by ``$CC`` (default
  ``gcc``) with what its ``--version`` prints, and ``$CFLAGS``: a compiler upgraded in place is a new key.

A file that changes changes the key, so an edited hook, template, twin or compiler is compiled
afresh, never handed an old FMU. ``TRACKINGBOX_PATCH_CACHE=0`` turns the cache off.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import logging
import os
import shutil
import subprocess
from collections.abc import Iterable
from pathlib import Path

from .. import config
from ..compiler import library_path
from ..compiler.library import cache_dir
from ..version import __version__

log = logging.getLogger(__name__)

#: The cache's size above which the least recently used FMUs are removed (MB).
LIMIT_MB = 512

_TREES: dict[str, tuple[tuple[tuple[str, int, int], ...], str]] = {}


def enabled() -> bool:
    """Whether compiled patches are kept between diagnoses (``TRACKINGBOX_PATCH_CACHE``)."""
    return bool(config.get("patch_cache"))


def tree_hash(root: Path, pattern: str) -> str:
    """Hash of the names and contents of the files *pattern* under *root* (a file: itself).

    Kept per process under the files' sizes and modification times: read again only when one changed.
    """
    root = Path(root).resolve()
    files = sorted(root.rglob(pattern)) if root.is_dir() else [root] if root.is_file() else []
    stamp = []
    for f in files:
        try:
            st = f.stat()
        except OSError:
            continue
        stamp.append((str(f.relative_to(root) if root.is_dir() else f.name), st.st_size, st.st_mtime_ns))
    stamps = tuple(stamp)
    known = _TREES.get(f"{root}|{pattern}")
    if known is not None and known[0] == stamps:
        return known[1]
    h = hashlib.sha256()
    for (name, _, _), f in zip(stamps, files):
        h.update(name.encode() + b"\0")
        h.update(f.read_bytes() + b"\0")
    digest = h.hexdigest()
    _TREES[f"{root}|{pattern}"] = (stamps, digest)
    return digest


def key(local: str, libraries: Iterable[Path] = ()) -> str:
    """The cache key of a patch whose work-folder key is *local*, compiled beside *libraries*."""
    h = hashlib.sha256(f"{__version__}\0{local}\0".encode())
    h.update(tree_hash(library_path(), "*.mo").encode())
    for lib in libraries:
        h.update(tree_hash(Path(lib), "*.mo").encode())
    h.update(tree_hash(Path(__file__).resolve().parent.parent / "compiler", "*.py").encode())
    h.update(f"\0{os.environ.get('CC', '')}\0{os.environ.get('CFLAGS', '')}\0{_tools()}".encode())
    h.update(f"\0{c_compiler(os.environ.get('CC') or 'gcc')}".encode())
    return h.hexdigest()


def c_compiler(cc: str) -> str:
    """Which C compiler *cc* is: its resolved path and the first line its ``--version`` prints.

    Asked once per process and file (its path, size and modification time), so an upgraded
    compiler gives another answer; ``-`` where there is none or it does not answer.
    """
    exe = shutil.which(cc)
    if exe is None:
        return f"{cc}=-"
    try:
        st = os.stat(exe)
    except OSError:
        return f"{cc}=-"
    return _version_of(os.path.realpath(exe), st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=8)
def _version_of(exe: str, size: int, mtime: int) -> str:
    try:
        out = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=60, check=False).stdout
    except (OSError, subprocess.SubprocessError):
        out = ""
    first = out.strip().splitlines()[0] if out.strip() else "-"
    return f"{exe}={first}"


@functools.lru_cache(maxsize=1)
def _tools() -> str:
    """Versions of the packages the embedded compile runs through (front end, export, C headers)."""
    out = []
    for name in ("rumoca", "casadi", "fmpy"):
        try:
            out.append(f"{name}={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            out.append(f"{name}=-")
    return ",".join(out)


def _entry(k: str) -> Path:
    return cache_dir() / "patches" / k[:2] / k


def fetch(k: str, fmu: Path) -> bool:
    """Copy the cached FMU of key *k* to *fmu*; False when there is none (or the cache is off)."""
    if not enabled():
        return False
    folder = _entry(k)
    kept = folder / fmu.name
    if not kept.is_file():
        return False
    try:
        fmu.parent.mkdir(parents=True, exist_ok=True)
        part = fmu.with_name(f".{fmu.name}.{os.getpid()}.part")
        shutil.copyfile(kept, part)
        os.replace(part, fmu)
        os.utime(folder)
    except OSError as exc:
        log.debug("compiled patch %s not taken from the cache: %s", kept, exc)
        return False
    log.info("compiled patch %s taken from the cache (%s)", fmu.name, folder)
    return True


def store(k: str, fmu: Path) -> None:
    """Keep the FMU *fmu* under key *k* (a cache that cannot be written is only slower)."""
    if not enabled():
        return
    folder = _entry(k)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        part = folder / f".{fmu.name}.{os.getpid()}.part"
        shutil.copyfile(fmu, part)
        os.replace(part, folder / fmu.name)
        trim()
    except OSError as exc:
        log.debug("compiled patch %s not cached: %s", fmu, exc)


def trim(limit_mb: float = LIMIT_MB) -> None:
    """Remove the least recently used entries while the cache holds more than *limit_mb*."""
    root = cache_dir() / "patches"
    entries = []
    for folder in root.glob("*/*"):
        try:
            size = sum(f.stat().st_size for f in folder.iterdir())
            entries.append((folder.stat().st_mtime, size, folder))
        except OSError:
            continue
    total = sum(e[1] for e in entries)
    for _, size, folder in sorted(entries):
        if total <= limit_mb * 1024 * 1024:
            break
        shutil.rmtree(folder, ignore_errors=True)
        total -= size
