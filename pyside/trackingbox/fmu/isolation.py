"""Foreign native code isolated: bounded extraction of an FMU archive and the canary run.

:func:`extract` unpacks an FMU with limits on entries and sizes; :func:`canary` runs the FMU's
first calls in a forked child once per FMU, so a binary that crashes or calls ``exit()`` is
one :class:`~trackingbox.errors.FMUError`, not the end of this process.
"""
from __future__ import annotations

import faulthandler
import logging
import os
import select
import shutil
import signal
import tempfile
import time
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3Slave
from fmpy.model_description import ModelDescription

from .. import config
from ..errors import FMUError
from ..supervise import fmu_timeout, note_output
from .info import MAX_ENTRIES, float_or_none

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------
# bounded extraction and the canary (foreign native code isolated)
# ---------------------------------------------------------------------------

def _max_bytes() -> int:
    return int(config.get("fmu_max_bytes"))


def _check_archive(path: Path, zf: zipfile.ZipFile) -> list[zipfile.ZipInfo]:
    """The archive's entries after the checks that need no extraction: count, names, links, declared size."""
    items = zf.infolist()
    if len(items) > MAX_ENTRIES:
        raise FMUError(f"FMU {path} has {len(items)} archive entries (at most {MAX_ENTRIES}): not extracted")
    total = 0
    for item in items:
        name = item.filename
        parts = name.replace("\\", "/").split("/")
        if (name.startswith(("/", "\\")) or "\\" in name or ":" in name or ".." in parts or "\x00" in name):
            raise FMUError(f"FMU {path} has an archive entry with an unsafe path {name[:120]!r} "
                           "(absolute, '..' or a drive): not extracted")
        mode = (item.external_attr >> 16) & 0o170000
        if mode == 0o120000:
            raise FMUError(f"FMU {path} has a symbolic link {name[:120]!r} in its archive: not extracted")
        total += item.file_size
    limit = _max_bytes()
    if total > limit:
        raise FMUError(f"FMU {path} would inflate to {total} bytes (at most {limit} bytes; "
                       "TRACKINGBOX_FMU_MAX_BYTES sets the limit): not extracted")
    return items


def extract(path: Path) -> str:
    """Extract *path* to a new temporary directory, bounded in entries and bytes; nothing left on failure.

    The sizes the archive declares are checked first; while inflating, the bytes
    actually written are counted too (a forged header cannot get past the limit).
    """
    tempdir = tempfile.mkdtemp(prefix="tbx-fmu-")
    try:
        limit, written = _max_bytes(), 0
        with zipfile.ZipFile(path) as zf:
            for item in _check_archive(path, zf):
                target = os.path.join(tempdir, *item.filename.split("/"))
                if item.is_dir():
                    os.makedirs(target, exist_ok=True)
                    continue
                os.makedirs(os.path.dirname(target), exist_ok=True)
                with zf.open(item) as src, open(target, "wb") as dst:
                    while True:
                        chunk = src.read(1 << 20)
                        if not chunk:
                            break
                        written += len(chunk)
                        if written > limit:
                            raise FMUError(f"FMU {path} inflates to more than {limit} bytes "
                                           "(TRACKINGBOX_FMU_MAX_BYTES sets the limit): not extracted")
                        dst.write(chunk)
        note_output(tempdir, True)  # removed by the console script's supervisor if this process dies
        return tempdir
    except FMUError:
        shutil.rmtree(tempdir, ignore_errors=True)
        raise
    except (OSError, zipfile.BadZipFile, EOFError, RuntimeError, ValueError, NotImplementedError) as exc:
        shutil.rmtree(tempdir, ignore_errors=True)
        raise FMUError(f"FMU {path} could not be extracted: {str(exc)[:200] or type(exc).__name__}") from None
    except BaseException:
        shutil.rmtree(tempdir, ignore_errors=True)
        raise


#: seconds one FMI call of the canary (and, under the supervisor, of the run) may take
#: (``TRACKINGBOX_FMU_TIMEOUT`` overrides; :func:`trackingbox.supervise.fmu_timeout`)
CANARY_TIMEOUT = config.setting("fmu_timeout").default
_CANARY_PASSED: set[tuple[Any, ...]] = set()


def _canary_timeout() -> float:
    return fmu_timeout()


def _canary_calls(tempdir: str, md: ModelDescription, interface: str,
                  phase: Callable[[str], None]) -> None:
    """In the canary process: load, instantiate, initialise, read the outputs, take one step, free."""
    v3 = str(md.fmiVersion).startswith("3")
    p = "fmi3" if v3 else "fmi2"
    Model, Slave = (FMU3Model, FMU3Slave) if v3 else (FMU2Model, FMU2Slave)
    kind = md.coSimulation if interface == "CoSimulation" else md.modelExchange
    cls = Slave if interface == "CoSimulation" else Model
    phase("the loading of its shared library")
    fmu = cls(guid=md.guid, unzipDirectory=tempdir, modelIdentifier=kind.modelIdentifier,
              instanceName="canary")
    phase(f"{p}Instantiate")
    fmu.instantiate()
    exp = md.defaultExperiment
    t0 = float_or_none(exp.startTime) if exp else None
    t0 = t0 or 0.0
    if not v3:
        phase("fmi2SetupExperiment")
        fmu.setupExperiment(startTime=t0)
    phase(f"{p}EnterInitializationMode")
    fmu.enterInitializationMode()
    phase(f"{p}ExitInitializationMode")
    fmu.exitInitializationMode()
    reals = [v.valueReference for v in md.modelVariables
             if v.causality == "output" and v.type in ("Real", "Float64")]
    if reals:
        phase(f"{p}GetFloat64" if v3 else "fmi2GetReal")
        (fmu.getFloat64 if v3 else fmu.getReal)(reals)
    if interface == "CoSimulation":
        step = (float_or_none(exp.stepSize) if exp else None) or 1e-3
        phase(f"{p}DoStep")
        fmu.doStep(currentCommunicationPoint=t0, communicationStepSize=step)
        if reals:
            phase(f"{p}GetFloat64" if v3 else "fmi2GetReal")
            (fmu.getFloat64 if v3 else fmu.getReal)(reals)
    phase(f"{p}Terminate")
    fmu.terminate()
    phase(f"{p}FreeInstance")
    fmu.freeInstance()


def canary(path: Path, tempdir: str, md: ModelDescription, interface: str) -> None:
    """Run the FMU's native code once in a forked process before this process loads it.

    A crash (signal), a call to ``exit()`` or a call that does not return within
    ``TRACKINGBOX_FMU_TIMEOUT`` seconds in loading, instantiation, initialisation,
    the first output read or the first step becomes an :class:`FMUError` naming
    the signal and the FMI function. Checked once per file (path, size, mtime) and
    interface in a process. An FMI call that merely reports an error is left to
    the normal path, which reports it with the FMU's own message.
    ``TRACKINGBOX_CANARY=0`` skips it (a trusted FMU; benchmarks of its cost).
    """
    try:
        st = path.stat()
        key: tuple[Any, ...] = (str(path.resolve()), st.st_size, st.st_mtime_ns, interface)
    except OSError:
        key = (str(path), interface)
    if key in _CANARY_PASSED or not hasattr(os, "fork") or not config.get("canary"):
        return
    timeout = _canary_timeout()
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child: report each phase, then the end, and leave
        code = 0
        try:
            os.close(read_fd)
            faulthandler.disable()  # a crash here is reported by the parent, not dumped on stderr

            def phase(name: str) -> None:
                os.write(write_fd, f"phase {name}\n".encode())

            try:
                _canary_calls(tempdir, md, interface, phase)
                os.write(write_fd, b"done\n")
            except Exception as exc:  # an FMI error status or a missing symbol: not a crash
                os.write(write_fd, f"failed {type(exc).__name__}\n".encode())
        finally:
            os._exit(code)
    os.close(write_fd)
    phase, ended, buffer = "starting", False, b""
    deadline = time.monotonic() + timeout
    try:
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                raise FMUError(f"FMU {path}: the FMU's binary did not return from {phase} within {timeout:g} s "
                               "(TRACKINGBOX_FMU_TIMEOUT sets the limit)")
            ready, _, _ = select.select([read_fd], [], [], min(left, 1.0))
            if not ready:
                continue
            chunk = os.read(read_fd, 4096)
            if not chunk:
                break
            buffer += chunk
            *lines, rest = buffer.split(b"\n")
            buffer = rest
            for line in lines:
                text = line.decode(errors="replace")
                if text.startswith("phase "):
                    phase = text[6:]
                    deadline = time.monotonic() + timeout
                elif text == "done" or text.startswith("failed"):
                    ended = True
        _, status = os.waitpid(pid, 0)
    finally:
        os.close(read_fd)
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = f"signal {sig}"
        raise FMUError(f"FMU {path}: the FMU's binary crashed ({name}) in {phase}")
    if not ended:
        raise FMUError(f"FMU {path}: the FMU's binary called exit({os.WEXITSTATUS(status)}) in {phase}")
    _CANARY_PASSED.add(key)
