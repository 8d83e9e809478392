"""Run a command in a forked child so that a crash of foreign native code still gives one error line.

:mod:`trackingbox.fmu` runs each FMU's native code once in a canary process
before loading it (loading, instantiation, initialisation, the first output read
and step). What the canary cannot see (a binary that crashes on its thousandth
``fmi2GetReal``, or calls ``exit()`` in the middle of a run) would still kill the
``trackingbox`` process with a bare exit 139. :func:`supervise` runs the whole
command in a forked child and waits: a child killed by a signal becomes
``error: the FMU's binary crashed (SIGSEGV) in fmi2GetReal`` (the FMI function
read from :mod:`faulthandler`'s dump of the child's Python stack), a child that
ends without finishing becomes ``error: ... called exit(0) ...``; otherwise the
child's exit code is returned. The cost is one ``fork`` per command.

The child dies with its parent (``PR_SET_PDEATHSIG`` on Linux): ``kill -9`` of
``trackingbox`` stops the run as it did before.
"""
from __future__ import annotations

import ctypes
import faulthandler
import os
import re
import shutil
import signal
import sys
import tempfile
import traceback
from collections.abc import Callable

#: innermost frame of fmpy's FMI wrappers in a faulthandler dump: (fmi2|fmi3|fmi1 module, method)
_FMPY_FRAME = re.compile(r'File "[^"]*fmpy[/\\](fmi[123])\.py", line \d+ in (\w+)')
#: environment variable naming the file where :func:`note_fmu` writes the FMU last opened
NOTE_ENV = "TRACKINGBOX_SUPERVISOR_NOTE"
#: environment variable naming the file where :func:`note_output` lists output directories being created
OUTPUTS_ENV = "TRACKINGBOX_SUPERVISOR_OUTPUTS"
_ANY_FRAME = re.compile(r'File "([^"]*)", line (\d+) in (\w+)')


def fmi_function(dump: str) -> str | None:
    r"""The FMI function a faulthandler *dump* was in, from its innermost fmpy frames, or None.

    >>> fmi_function('Current thread 0x1 (most recent call first):\n'
    ...              '  File "/x/fmpy/fmi1.py", line 361 in _call\n'
    ...              '  File "/x/fmpy/fmi2.py", line 196 in fmi2GetReal\n'
    ...              '  File "/x/trackingbox/fmu.py", line 9 in read')
    'fmi2GetReal'
    >>> fmi_function('  File "/x/fmpy/fmi3.py", line 418 in doStep')
    'fmi3DoStep'
    >>> fmi_function('  File "/x/fmpy/fmi1.py", line 90 in __init__') is None
    True
    """
    for module, method in _FMPY_FRAME.findall(dump):
        if re.fullmatch(r"fmi[123][A-Z]\w*", method):
            return method
        if method.startswith("_") or module == "fmi1" or method == "w":
            continue
        return f"{module}{method[0].upper()}{method[1:]}"
    return None


def _describe(dump: str, fmu_path: str = "") -> str:
    name = fmi_function(dump)
    fmu = f"FMU {fmu_path}: " if fmu_path else ""
    if name is not None:
        return f"{fmu}the FMU's binary crashed ({{signal}}) in {name}"
    if _FMPY_FRAME.search(dump):
        return f"{fmu}the FMU's binary crashed ({{signal}}) while its shared library was loaded"
    frame = _ANY_FRAME.search(dump)
    where = f" in {os.path.basename(frame.group(1))}:{frame.group(2)} ({frame.group(3)})" if frame else ""
    return f"trackingbox crashed ({{signal}}){where}: please report this with the command line"


def _die_with_parent() -> None:
    """Linux: the child gets SIGKILL when the supervising process dies."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def supervise(run: Callable[[list[str]], int], argv: list[str]) -> int:
    """Run ``run(argv)`` in a forked child; return its exit code or report how it died (exit 2)."""
    sys.stdout.flush()
    sys.stderr.flush()
    dump = tempfile.TemporaryFile(prefix="trackingbox-fault-")
    note = tempfile.NamedTemporaryFile(prefix="trackingbox-fmu-", delete=False)
    note.close()
    outputs = tempfile.NamedTemporaryFile(prefix="trackingbox-out-", delete=False)
    outputs.close()
    read_fd, write_fd = os.pipe()
    parent = os.getpid()
    pid = os.fork()
    if pid == 0:  # the child: the command itself
        os.close(read_fd)
        _die_with_parent()
        if os.getppid() != parent:  # the parent died before prctl took effect
            os._exit(1)
        faulthandler.enable(file=dump, all_threads=False)
        os.environ[NOTE_ENV] = note.name
        os.environ[OUTPUTS_ENV] = outputs.name
        code: int = 1
        try:
            code = int(run(argv) or 0)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            if exc.code is not None and not isinstance(exc.code, int):
                print(exc.code, file=sys.stderr)
        except BaseException:  # what the interpreter would print
            traceback.print_exc()
            code = 1
        os.write(write_fd, f"done {code}\n".encode())
        os.close(write_fd)
        sys.exit(code)
    os.close(write_fd)
    previous = {}
    for sig in (signal.SIGINT, signal.SIGQUIT):
        previous[sig] = signal.signal(sig, signal.SIG_IGN)  # the child gets them from the terminal

    def forward(signum: int, frame: object) -> None:
        try:
            os.kill(pid, signum)
        except ProcessLookupError:
            pass

    for sig in (signal.SIGTERM, signal.SIGHUP):
        previous[sig] = signal.signal(sig, forward)
    try:
        _, status = os.waitpid(pid, 0)
        with os.fdopen(read_fd, "rb") as fh:
            report = fh.read().decode(errors="replace")
        with open(note.name, encoding="utf-8", errors="replace") as fh:
            fmu_path = fh.read().strip()
        with open(outputs.name, encoding="utf-8", errors="replace") as fh:
            created = _pending_outputs(fh.read())
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for name in (note.name, outputs.name):
            try:
                os.unlink(name)
            except OSError:
                pass
    finished = report.startswith("done ")
    if not finished:
        # the child died inside an output_dir block: remove what it created (nothing half-written)
        for path in created:
            shutil.rmtree(path, ignore_errors=True)
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig == signal.SIGKILL and not finished:
            # killed from outside (kill -9, the OOM killer): say so, exit as a killed process would
            print("error: the run was killed (SIGKILL)", file=sys.stderr)
            return 128 + sig
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = f"signal {sig}"
        dump.seek(0)
        text = dump.read().decode(errors="replace")
        message = _describe(text, fmu_path).format(signal=name)
        if finished:
            print(f"warning: {message} after the command had finished (its results are complete)",
                  file=sys.stderr)
            return int(report.split()[1])
        print(f"error: {message}", file=sys.stderr)
        return 2
    code = os.WEXITSTATUS(status)
    if not finished:
        culprit = f"FMU {fmu_path}: the FMU's binary" if fmu_path else "foreign native code (an FMU's binary)"
        print(f"error: {culprit} called exit({code}) before the command finished", file=sys.stderr)
        return 2
    return code


def note_fmu(path: object) -> None:
    """Under :func:`supervise`: remember *path* as the FMU whose native code now runs (for the error line)."""
    target = os.environ.get(NOTE_ENV)
    if not target:
        return
    try:
        with open(target, "w", encoding="utf-8") as fh:
            fh.write(str(path))
    except OSError:
        pass


def note_output(path: object, created: bool) -> None:
    """Under :func:`supervise`: *path* (a directory that did not exist) is being created (*created*) or is complete.

    Directories still being created when the child dies are removed by the supervisor.
    """
    target = os.environ.get(OUTPUTS_ENV)
    if not target:
        return
    try:
        with open(target, "a", encoding="utf-8") as fh:
            fh.write(f"{'+' if created else '-'}{os.path.abspath(str(path))}\n")
    except OSError:
        pass


def _pending_outputs(text: str) -> list[str]:
    r"""Directories noted as being created and not noted complete.

    >>> _pending_outputs("+/a\n+/b\n-/a\n")
    ['/b']
    """
    pending: dict[str, None] = {}
    for line in text.splitlines():
        if line.startswith("+"):
            pending[line[1:]] = None
        elif line.startswith("-"):
            pending.pop(line[1:], None)
    return list(pending)
