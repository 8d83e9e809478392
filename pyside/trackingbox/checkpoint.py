"""Restart points that a ``kill -9`` cannot corrupt and ``--resume`` never half-trusts.

Two forms:

* :class:`CheckpointFile`: one JSON document (the tracking loop's
  ``state_dict()``), replaced atomically, sealed (key ``sha256``) with the
  SHA-256 of its own canonical content and of the streamed file it vouches for (the first ``csv_bytes`` of
  ``tracking.csv``). :meth:`CheckpointFile.read` refuses a document that does
  not parse, whose seal does not match, or whose CSV is shorter than recorded or
  differs from what was written.
* :class:`Journal`: an append-only record of every evaluation of a
  deterministic search (estimation), one line per batch, each line sealed
  with its SHA-256. Resuming re-runs the search with the recorded values served
  from the journal instead of simulating again, so the search takes the same
  path and gives the same bits; the population of the global stage and the
  state of the local stage are what that replay rebuilds. Each batch is one
  ``write()`` of whole lines, so a killed process leaves whole lines only; a
  truncated or altered line is refused, as is a journal of another run.

A checkpoint of another spec or version is refused by its reader with the
reason (:class:`~trackingbox.errors.CheckpointError`).
"""
from __future__ import annotations

import base64
import binascii
import hashlib
import json
import logging
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .errors import CheckpointError, StaleCheckpointError
from .io import write_text_atomic

log = logging.getLogger(__name__)

__all__ = ["CheckpointFile", "Journal", "file_digest"]

_SEAL = "sha256"


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def file_digest(path: str | os.PathLike[str], chunk: int = 1 << 20) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


class _PrefixHash:
    """SHA-256 of the first *n* bytes of an append-only file, extended incrementally."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.size = 0
        self.hash = hashlib.sha256()

    def upto(self, size: int) -> str:
        if size < self.size:  # the file was cut back (a resume): start over
            self.size, self.hash = 0, hashlib.sha256()
        with open(self.path, "rb") as fh:
            fh.seek(self.size)
            remaining = size - self.size
            while remaining > 0:
                block = fh.read(min(remaining, 1 << 20))
                if not block:
                    raise CheckpointError(f"{self.path} is {self.size} bytes long, shorter than the "
                                          f"{size} bytes its checkpoint records")
                self.hash.update(block)
                self.size += len(block)
                remaining -= len(block)
        return self.hash.hexdigest()


class CheckpointFile:
    """A sealed JSON checkpoint beside a streamed CSV.

    Parameters
    ----------
    path : path
        The checkpoint (``checkpoint.json``).
    stream : path, optional
        The append-only file the checkpoint vouches for; the state must then
        hold its valid length under ``state[stream_key]["csv_bytes"]``.
    stream_key : str
        Where in the state the stream's length is.
    """

    def __init__(self, path: str | os.PathLike[str], stream: str | os.PathLike[str] | None = None, *,
                 stream_key: str = "output") -> None:
        self.path = Path(path)
        self.stream = Path(stream) if stream is not None else None
        self.stream_key = stream_key
        self._prefix = _PrefixHash(self.stream) if self.stream is not None else None

    def _stream_bytes(self, state: Mapping[str, Any]) -> int:
        try:
            return int(state[self.stream_key]["csv_bytes"])
        except (KeyError, TypeError, ValueError):
            raise CheckpointError(f"checkpoint {self.path} has no valid '{self.stream_key}.csv_bytes'; "
                                  "run without --resume to start over") from None

    def write(self, state: Mapping[str, Any]) -> None:
        """Seal *state* (a JSON-able mapping) and replace the checkpoint atomically."""
        if _SEAL in state:
            raise ValueError(f"a checkpoint state cannot have a key {_SEAL!r}")
        seal: dict[str, Any] = {"state": _digest(_canonical(state))}
        if self._prefix is not None:
            n = self._stream_bytes(state)
            seal["stream"] = {"name": self.stream.name, "bytes": n, "sha256": self._prefix.upto(n)}
        write_text_atomic(self.path, json.dumps({**state, _SEAL: seal}, indent=1, allow_nan=False) + "\n")

    def read(self) -> dict[str, Any]:
        """The checkpoint's state; :class:`CheckpointError` unless every seal matches."""
        where = f"checkpoint {self.path}"
        hint = "; delete it or run without --resume to start over"
        try:
            raw = self.path.read_bytes()
        except OSError as exc:
            raise CheckpointError(f"{where} cannot be read ({exc.strerror or exc}){hint}") from None
        try:
            state = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError):
            raise CheckpointError(f"{where} is truncated or is not JSON ({len(raw)} bytes){hint}") from None
        seal = state.pop(_SEAL, None) if isinstance(state, dict) else None
        if not isinstance(seal, dict):
            raise CheckpointError(f"{where} has no {_SEAL} seal: not a checkpoint of this version{hint}")
        try:
            canonical = _canonical(state)
        except ValueError:
            canonical = ""
        if seal.get("state") != _digest(canonical):
            raise CheckpointError(f"{where} is corrupt: its content does not match its SHA-256 seal{hint}")
        if self._prefix is not None:
            assert self.stream is not None
            stream = seal.get("stream") or {}
            n = self._stream_bytes(state)
            if stream.get("bytes") != n:
                raise CheckpointError(f"{where} is corrupt: its seal and its state disagree on the length "
                                      f"of {self.stream.name}{hint}")
            if not self.stream.exists():
                raise CheckpointError(f"{where} vouches for {self.stream} ({n} bytes), which is missing{hint}")
            size = self.stream.stat().st_size
            if size < n:
                raise CheckpointError(f"{self.stream} is {size} bytes long, shorter than the {n} bytes "
                                      f"{where} records (the file was cut or replaced){hint}")
            if self._prefix.upto(n) != stream.get("sha256"):
                raise CheckpointError(f"the first {n} bytes of {self.stream} differ from what {where} "
                                      f"recorded (the file was edited or replaced){hint}")
        return state


def _canonical(state: Mapping[str, Any]) -> str:
    """The text the seal is taken over (floats by ``repr``: reading them back gives the same bits)."""
    return json.dumps(state, sort_keys=True, separators=(",", ":"), allow_nan=False)


# --------------------------------------------------------------------------- journal

def _key(prefix: str, x: Iterable[float]) -> str:
    return prefix + ":" + ",".join(float(v).hex() for v in np.asarray(x, dtype=float).ravel())


def _encode(value: Any) -> Any:
    if isinstance(value, np.ndarray):  # the float64 bits, little-endian, base64: exact and a third of JSON's size
        return {"f8": base64.b64encode(np.ascontiguousarray(value, dtype="<f8").tobytes()).decode("ascii")}
    if isinstance(value, dict):
        return {"d": {str(k): float(v) for k, v in value.items()}}
    return float(value)


def _decode(value: Any) -> Any:
    if isinstance(value, dict) and "f8" in value:
        return np.frombuffer(base64.b64decode(value["f8"], validate=True), dtype="<f8").astype(float)
    if isinstance(value, dict) and "d" in value:
        return {k: float(v) for k, v in value["d"].items()}
    return float(value)


class Journal:
    """Append-only, line-sealed record of a deterministic search's evaluations.

    Parameters
    ----------
    path : path or None
        The journal file; ``None``: nothing is recorded (a plain run).
    identity : mapping
        What makes two runs the same search (inputs' digests, settings). A
        journal with another identity is refused on resume.
    resume : bool
        Load the journal at *path* (if it exists) and serve its values; else
        start a new one (an old journal is replaced).

    Notes
    -----
    Values are floats, float arrays or ``{name: float}`` mappings; JSON
    writes floats by ``repr``, which reads back to the same bits, and arrays
    as their float64 bytes (base64). Points are keyed by their exact bits
    (``float.hex``).
    """

    VERSION = 1

    def __init__(self, path: str | os.PathLike[str] | None, identity: Mapping[str, Any], *,
                 resume: bool = False) -> None:
        self.path = Path(path) if path is not None else None
        self.identity = json.loads(json.dumps(dict(identity)))
        self.values: dict[str, Any] = {}
        self.served = 0
        self._fd: int | None = None
        if self.path is None:
            return
        if resume and self.path.exists():
            self._load()
            self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)
            log.info("resuming from %s: %d evaluations recorded", self.path, len(self.values))
        else:
            if resume:
                log.info("no journal %s; starting from the beginning", self.path)
            write_text_atomic(self.path, self._line({"journal": "trackingbox", "version": self.VERSION,
                                                     "identity": self.identity}))
            self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)

    @staticmethod
    def _line(obj: Any) -> str:
        body = json.dumps(obj, separators=(",", ":"))
        return f"{_digest(body)[:32]} {body}\n"

    def _load(self) -> None:
        assert self.path is not None
        hint = "; delete it or run without --resume to start over"
        try:
            text = self.path.read_bytes().decode("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise CheckpointError(f"journal {self.path} cannot be read ({exc}){hint}") from None
        lines = text.split("\n")
        if lines[-1] != "":
            raise CheckpointError(f"journal {self.path} is truncated: line {len(lines)} is incomplete{hint}")
        entries = []
        for i, line in enumerate(lines[:-1], start=1):
            seal, _, body = line.partition(" ")
            if _digest(body)[:32] != seal:
                raise CheckpointError(f"journal {self.path} is corrupt at line {i}: the line does not match "
                                      f"its SHA-256 seal{hint}")
            try:
                entries.append(json.loads(body))
            except ValueError:
                raise CheckpointError(f"journal {self.path} is corrupt at line {i}{hint}") from None
        if not entries or not isinstance(entries[0], dict) or entries[0].get("journal") != "trackingbox":
            raise CheckpointError(f"journal {self.path} has no trackingbox header{hint}")
        head = entries[0]
        if head.get("version") != self.VERSION or head.get("identity") != self.identity:
            theirs, ours = head.get("identity") or {}, self.identity
            diff = sorted(k for k in set(theirs) | set(ours) if theirs.get(k) != ours.get(k))
            raise StaleCheckpointError(f"journal {self.path} was written by another run (differs in: "
                                  f"{', '.join(diff) or 'version'}); run without --resume to start over")
        for i, batch in enumerate(entries[1:], start=2):
            try:
                for key, value in batch:
                    self.values[str(key)] = _decode(value)
            except (TypeError, ValueError, KeyError, binascii.Error):
                raise CheckpointError(f"journal {self.path} has a malformed entry at line {i}{hint}") from None

    def _append(self, items: Sequence[tuple[str, Any]]) -> None:
        if self._fd is None or not items:
            return
        data = self._line([[k, _encode(v)] for k, v in items]).encode("utf-8")
        os.write(self._fd, data)  # one write: a killed process leaves whole lines

    def call(self, prefix: str, fn: Callable[[Any], Any], x: Any) -> Any:
        """``fn(x)``, from the journal when recorded (then counted in :attr:`served`)."""
        key = _key(prefix, x)
        if key in self.values:
            self.served += 1
            return _copy(self.values[key])
        value = fn(x)
        if self.path is not None:
            self.values[key] = _copy(value)
            self._append([(key, value)])
        return value

    def map(self, prefix: str, fn: Callable[[Any], Any], xs: Iterable[Any],
            mapper: Callable[..., Iterable[Any]] | None = None) -> list[Any]:
        """``[fn(x) for x in xs]`` with the unrecorded ones computed by *mapper* (e.g. ``pool.map``)."""
        xs = list(xs)
        keys = [_key(prefix, x) for x in xs]
        out: list[Any] = [None] * len(xs)
        todo = []
        for i, key in enumerate(keys):
            if key in self.values:
                out[i] = _copy(self.values[key])
                self.served += 1
            else:
                todo.append(i)
        if todo:
            points = [xs[i] for i in todo]
            computed = list(mapper(fn, points)) if mapper is not None else [fn(p) for p in points]
            new = []
            for i, value in zip(todo, computed):
                out[i] = value
                if self.path is not None:
                    self.values[keys[i]] = _copy(value)
                    new.append((keys[i], value))
            self._append(new)
        return out

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def _copy(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, dict):
        return dict(value)
    return value
