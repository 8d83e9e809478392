"""Small file helpers: write-then-rename so that nothing is ever half-written."""
from __future__ import annotations

import contextlib
import os
import shutil
import stat as _stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from .errors import OutputError, TrackingError
from .supervise import note_output


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside *target*; on success rename it onto *target*.

    If the body raises, the temporary file is removed and *target* is untouched.

    Examples
    --------
    >>> import tempfile
    >>> target = Path(tempfile.mkdtemp()) / "result.txt"
    >>> _ = target.write_text("old")
    >>> try:
    ...     with atomic_path(target) as tmp:
    ...         _ = tmp.write_text("half-writ")
    ...         raise RuntimeError("failed while writing")
    ... except RuntimeError:
    ...     pass
    >>> target.read_text(), sorted(p.name for p in target.parent.iterdir())
    ('old', ['result.txt'])
    >>> with atomic_path(target) as tmp:
    ...     _ = tmp.write_text("new")
    >>> target.read_text(), sorted(p.name for p in target.parent.iterdir())
    ('new', ['result.txt'])
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if tmp_path.exists():
            # mkstemp creates 0600 files; give the result the usual permissions
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp_path, 0o666 & ~umask)
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_text_atomic(target: str | os.PathLike[str], text: str) -> None:
    """Write *text* to *target* atomically (UTF-8)."""
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _shown(path: str, limit: int = 120) -> str:
    """*path* for a message: at most *limit* characters (the middle elided)."""
    text = path.replace("\x00", "\\0")
    return text if len(text) <= limit else f"{text[:limit // 2]}...{text[-(limit // 2):]}"


def user_path(value: str | os.PathLike[str], what: str) -> Path:
    """*value* as a :class:`Path` with ``~`` expanded, else a refusal naming *what*.

    Refuses (``TrackingError``) an empty path, a NUL byte and an unknown ``~user``.

    >>> user_path("a/b.csv", "--out")
    PosixPath('a/b.csv')
    >>> user_path("", "--out")
    Traceback (most recent call last):
    ...
    trackingbox.errors.TrackingError: --out: the path is empty
    """
    text = os.fspath(value)
    if isinstance(text, bytes):  # pragma: no cover - os.fspath of a str path
        text = os.fsdecode(text)
    if not text:
        raise TrackingError(f"{what}: the path is empty")
    if "\x00" in text:
        raise TrackingError(f"{what} {_shown(text)!r}: a path cannot contain a NUL character")
    if text.startswith("~"):
        expanded = os.path.expanduser(text)
        if expanded.startswith("~"):
            user = text[1:].split("/", 1)[0]
            raise TrackingError(f"{what} {_shown(text)!r}: there is no user {user!r} whose home '~{user}' names")
        text = expanded
    return Path(text)


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except (OSError, RuntimeError, ValueError):
        return False


def check_output(value: str | os.PathLike[str], what: str, *, kind: str = "file",
                 inputs: Iterable[str | os.PathLike[str]] = ()) -> Path:
    """Check, before any work, that *value* can be written as an output *kind* (``"file"`` or ``"dir"``).

    Parameters
    ----------
    value
        The output location the user gave.
    what
        How the user gave it, for messages (``"-o"``, ``"--report"``).
    kind
        ``"file"``: a file written atomically (an existing regular file is replaced);
        ``"dir"``: a directory (an existing one is written into).
    inputs
        Files the command reads: the output may not be one of them.

    Returns
    -------
    Path
        The output location (``~`` expanded).

    Raises
    ------
    OutputError
        The path is empty, has a NUL, names an unknown ``~user``, is too long,
        is an input, is an existing directory (file) or a non-directory (dir),
        lies under a file, or its nearest existing directory is not writable.
    """
    try:
        path = user_path(value, what)
    except TrackingError as exc:
        raise OutputError(str(exc)) from None
    shown = _shown(str(path))
    for item in inputs:
        if _same(path, Path(item)):
            raise OutputError(f"{what} {shown}: it is an input of this command; write the output elsewhere")
    try:
        st = path.lstat() if path.is_symlink() else path.stat()
        exists = True
    except FileNotFoundError:
        exists = False
    except NotADirectoryError:
        raise OutputError(f"{what} {shown}: a parent of it is a file, not a directory") from None
    except OSError as exc:
        raise OutputError(f"{what} {shown}: cannot be used as an output ({exc.strerror or exc})") from None
    if exists:
        if kind == "file" and _stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{what} {shown}: is an existing directory; give a file name")
        if kind == "file" and not _stat.S_ISREG(st.st_mode):
            raise OutputError(f"{what} {shown}: exists and is not a regular file")
        if kind == "dir" and not _stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{what} {shown}: exists and is not a directory")
    # the nearest existing directory must be a writable directory
    probe = path if (exists and kind == "dir") else path.parent
    probe = Path(os.path.abspath(probe))
    while True:
        try:
            st = probe.stat()
            break
        except FileNotFoundError:
            probe = probe.parent
        except NotADirectoryError:
            raise OutputError(f"{what} {shown}: a parent of it is a file, not a directory") from None
        except OSError as exc:
            raise OutputError(f"{what} {shown}: cannot be used as an output ({exc.strerror or exc})") from None
    if not _stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{what} {shown}: {_shown(str(probe))} is a file, not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OutputError(f"{what} {shown}: directory {_shown(str(probe))} is not writable")
    try:
        name_max = os.pathconf(probe, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    longest = max((len(os.fsencode(part)) for part in path.parts), default=0)
    if longest > name_max or len(os.fsencode(os.path.abspath(path))) >= 4096:
        raise OutputError(f"{what} {shown}: the path is too long for the file system")
    return path


@contextlib.contextmanager
def output_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield *path*; if the body fails, remove whatever of it the body created.

    The directories of *path* that did not exist on entry (from the first
    missing one down) are deleted with their contents when the body raises, so a
    refused or failed run leaves the output location as it found it. An existing
    directory is never deleted (files the body added to it stay: write them with
    :func:`atomic_path`). Under the console script's supervisor
    (:mod:`trackingbox.supervise`) the same happens when the process dies in the
    body (an FMU's binary crashed).

    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> try:
    ...     with output_dir(root / "run" / "track") as out:
    ...         out.mkdir(parents=True)
    ...         _ = (out / "tracking.csv").write_text("half")
    ...         raise RuntimeError("inputs invalid")
    ... except RuntimeError:
    ...     pass
    >>> sorted(root.iterdir())
    []
    """
    path = Path(path)
    first_missing: Path | None = None
    probe = Path(os.path.abspath(path))
    while not probe.exists() and probe != probe.parent:
        first_missing = probe
        probe = probe.parent
    if first_missing is not None:
        note_output(first_missing, True)
    try:
        yield path
    except Exception:  # not KeyboardInterrupt: an interrupted run keeps its checkpoint
        if first_missing is not None and first_missing.exists():
            shutil.rmtree(first_missing, ignore_errors=True)
        raise
    finally:
        if first_missing is not None:
            note_output(first_missing, False)
