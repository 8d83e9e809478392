"""Run a command in a forked child so that a crash or hang of foreign native code still gives one error line.

:mod:`trackingbox.fmu` runs each FMU's native code once in a canary process
before loading it (loading, instantiation, initialisation, the first output read
and step). What the canary cannot see (a binary that crashes on its thousandth
``fmi2GetReal``, hangs in its thousandth ``fmi2DoStep`` or calls ``exit()`` in
the middle of a run) would still kill the ``trackingbox`` process with a bare
exit 139, or hang it forever. :func:`supervise` runs the whole command in a
forked child and waits: a child killed by a signal becomes
``error: the FMU's binary crashed (SIGSEGV) in fmi2GetReal`` (the FMI function
read from :mod:`faulthandler`'s dump of the child's Python stack), a child that
ends without finishing becomes ``error: ... called exit(0) ...``; otherwise the
child's exit code is returned. The cost is one ``fork`` per command.

In the child a :class:`Watchdog` thread bounds every FMI call: ctypes releases
the GIL during a foreign call, so the thread can read the main thread's stack
(``sys._current_frames()``) every :data:`WATCHDOG_POLL` s. When the innermost
frame of fmpy's FMI wrappers (the same frame object: the same call) has been
there longer than ``TRACKINGBOX_FMU_TIMEOUT`` s (60, the canary's limit too),
or one call of the native stepper into the FMU (:mod:`trackingbox.native`,
which calls it from C and counts its calls: the same count is the same call)
has run that long, the child reports it and ends; the supervisor prints
``error: the FMU's binary (twin.fmu) did not return from fmi2DoStep within 60 s
(TRACKINGBOX_FMU_TIMEOUT)`` and exits 2. Many short calls never trip it.
``TRACKINGBOX_WATCHDOG=0`` turns it off. In every such ending, the directories
the child was creating (:func:`note_output`) are removed.

The child dies with its parent (``PR_SET_PDEATHSIG`` on Linux): ``kill -9`` of
``trackingbox`` stops the run as it did before.
"""
from __future__ import annotations

import ctypes
import faulthandler
import json
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from types import FrameType

from . import config, native

#: innermost frame of fmpy's FMI wrappers in a faulthandler dump: (fmi2|fmi3|fmi1 module, method)
_FMPY_FRAME = re.compile(r'File "[^"]*fmpy[/\\](fmi[123])\.py", line \d+ in (\w+)')
#: environment variable naming the file where :func:`note_fmu` writes the FMU last opened
NOTE_ENV = config.setting("supervisor_note").env
#: environment variable naming the file where :func:`note_output` lists output directories being created
OUTPUTS_ENV = config.setting("supervisor_outputs").env
_ANY_FRAME = re.compile(r'File "([^"]*)", line (\d+) in (\w+)')
#: an fmpy FMI wrapper module's file name, as in a code object's ``co_filename``
_FMPY_FILE = re.compile(r"fmpy[/\\](fmi[123])\.py$")
#: seconds one FMI call may take, in the canary and under the watchdog (``TRACKINGBOX_FMU_TIMEOUT`` overrides)
FMU_TIMEOUT = config.setting("fmu_timeout").default
#: seconds between two looks of the watchdog at the main thread's stack
WATCHDOG_POLL = 0.5


def fmu_timeout() -> float:
    """``TRACKINGBOX_FMU_TIMEOUT`` in seconds (a positive finite number; :mod:`trackingbox.config`)."""
    return float(config.get("fmu_timeout"))


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
    return _fmi_name(_FMPY_FRAME.findall(dump))


def _fmi_name(frames: list[tuple[str, str]]) -> str | None:
    """The FMI function from fmpy frames ``(module, method)``, innermost first, or None."""
    for module, method in frames:
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


#: FMU extraction directory -> FMU path, in this process (:func:`note_fmu`): names the FMU of a stuck call
_FMU_DIRS: dict[str, str] = {}


class Watchdog:
    """A daemon thread that reports an FMI call of one thread that has not returned within *timeout* s.

    Every *poll* s it reads the watched thread's stack (``sys._current_frames()``;
    ctypes releases the GIL during the foreign call, so the thread runs) and keeps
    the innermost frame of fmpy's FMI wrappers. When the same frame object (the
    same call: a frame object belongs to one call, and the reference held here
    keeps it from being reused) is still there after *timeout* s, it calls
    ``on_timeout(function, fmu, timeout)`` once for that call: *function* is the
    FMI function (``"fmi2DoStep"``), *fmu* the FMU's path or ``""``. The FMU
    calls that :mod:`trackingbox.native` makes from C have no such frame; for
    them it reads the library's count of its FMI calls
    (:func:`trackingbox.native.fmi_call`): one call in progress whose count has
    not moved for *timeout* s is reported the same way, naming the FMU last
    opened. (With native steppers running in several threads of one process
    the count is shared: a hang in one is then seen only once the others stop
    calling.)

    Parameters
    ----------
    on_timeout
        What to do; under :func:`supervise` it reports and ends the process.
    timeout
        Seconds; default :func:`fmu_timeout` (``TRACKINGBOX_FMU_TIMEOUT``, 60).
    poll
        Seconds between two looks (:data:`WATCHDOG_POLL`): the cost is one stack walk per look.
    thread_id
        The watched thread's ident; default the main thread.
    """

    def __init__(self, on_timeout: Callable[[str, str, float], None], *, timeout: float | None = None,
                 poll: float = WATCHDOG_POLL, thread_id: int | None = None) -> None:
        self.timeout = fmu_timeout() if timeout is None else float(timeout)
        self.poll = float(poll)
        self.thread_id = threading.main_thread().ident if thread_id is None else thread_id
        self.fired: list[tuple[str, str, float]] = []
        self._on_timeout = on_timeout
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="trackingbox-fmu-watchdog", daemon=True)

    def start(self) -> Watchdog:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join()

    def __enter__(self) -> Watchdog:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _look(self) -> tuple[FrameType, str] | None:
        """The innermost fmpy FMI frame of the watched thread and the FMI function's name, or None."""
        frame: FrameType | None = sys._current_frames().get(self.thread_id)  # type: ignore[arg-type]
        watched: FrameType | None = None
        names: list[tuple[str, str]] = []
        while frame is not None:
            match = _FMPY_FILE.search(frame.f_code.co_filename)
            if match:
                watched = watched or frame
                names.append((match.group(1), frame.f_code.co_name))
            elif watched is not None:  # the wrappers' frames are contiguous: the call is named
                break
            frame = frame.f_back
        if watched is None:
            return None
        return watched, _fmi_name(names) or "a call into its shared library"

    @staticmethod
    def _native_call() -> tuple[int, str] | None:
        """The native library's FMI call in progress (``(seq, name)``, seq odd), else None.

        The steppers and the tracking rows in C (:mod:`trackingbox.native`)
        call the FMU from C, under no fmpy frame; the library counts its FMI
        calls (:func:`trackingbox.native.fmi_call`), and the same call is the
        same odd count.
        """
        call = native.fmi_call()  # the library imported with this module: never seen half-initialised
        return call if call is not None and call[0] % 2 == 1 else None

    def _fire(self, function: str, fmu: str) -> None:
        self.fired.append((function, fmu, self.timeout))
        self._on_timeout(function, fmu, self.timeout)

    def _watch(self) -> None:
        current: FrameType | None = None
        reported: FrameType | None = None
        since = 0.0
        native: tuple[int, float] | None = None  # (seq, since) of the native FMI call in progress
        native_reported: int | None = None
        while not self._stop.wait(self.poll):
            now = time.monotonic()
            call = self._native_call()
            if call is None:
                native = None
            elif native is None or call[0] != native[0]:
                native = (call[0], now)
            elif call[0] != native_reported and now - native[1] >= self.timeout:
                native_reported = call[0]  # once per call
                self._fire(call[1], _fmu_of(None))
            seen = self._look()
            if seen is None or seen[0] is not current:
                current = None if seen is None else seen[0]
                since = now
                continue
            if current is not reported and now - since >= self.timeout:
                reported = current  # once per call
                self._fire(seen[1], _fmu_of(current))
            seen = None


def _fmu_of(frame: FrameType | None) -> str:
    """The FMU whose extraction directory the fmpy object of *frame* (``self``) was loaded from, else the last noted."""
    try:
        owner = frame.f_locals.get("self") if frame is not None else None
        directory = getattr(owner, "unzipDirectory", None)
        if directory and os.path.realpath(directory) in _FMU_DIRS:
            return _FMU_DIRS[os.path.realpath(directory)]
    except Exception:  # noqa: BLE001 - a name for the message only
        pass
    target = config.get("supervisor_note")
    if target:
        try:
            with open(target, encoding="utf-8", errors="replace") as fh:
                return fh.read().strip()
        except OSError:
            pass
    return ""


#: what the command's simulation is doing now (:func:`note_phase`), for the watchdog's error line
_PHASE = [""]


def note_phase(text: str = "") -> None:
    """Name what the simulation runs now (e.g. a window's warm-up; ``""``: nothing special).

    Cheap (one assignment): the watchdog adds it to its error line, so a hang in
    an FMU's binary says in which part of the run it happened.
    """
    _PHASE[0] = text


def timeout_message(function: str, fmu: str, timeout: float, phase: str = "") -> str:
    """The error line's text for an FMI call that did not return.

    >>> timeout_message("fmi2DoStep", "/data/twin.fmu", 60.0)
    "the FMU's binary (twin.fmu) did not return from fmi2DoStep within 60 s (TRACKINGBOX_FMU_TIMEOUT)"
    >>> timeout_message("fmi2DoStep", "/data/twin.fmu", 60.0, "the warm-up before the training window").endswith(
    ...     "within 60 s (TRACKINGBOX_FMU_TIMEOUT) during the warm-up before the training window")
    True
    """
    who = f"the FMU's binary ({os.path.basename(fmu)})" if fmu else "foreign native code (an FMU's binary)"
    during = f" during {phase}" if phase else ""
    return f"{who} did not return from {function} within {timeout:g} s (TRACKINGBOX_FMU_TIMEOUT){during}"


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
        report_lock = threading.Lock()

        def hung(function: str, fmu: str, timeout: float) -> None:
            # the main thread is stuck in foreign code: say where, then end the whole process
            with report_lock:
                doc = json.dumps({"function": function, "fmu": fmu, "timeout": timeout, "phase": _PHASE[0]})
                os.write(write_fd, f"timeout {doc}\n".encode())
                os._exit(2)

        watchdog = Watchdog(hung) if config.get("watchdog") else None
        if watchdog is not None:
            watchdog.start()
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
        report_lock.acquire()  # held to the end: a late watchdog report cannot follow "done"
        if watchdog is not None:
            watchdog._stop.set()
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
    if report.startswith("timeout "):
        try:
            doc = json.loads(report[len("timeout "):].splitlines()[0])
            message = timeout_message(str(doc["function"]), str(doc["fmu"]), float(doc["timeout"]),
                                      str(doc.get("phase") or ""))
        except (ValueError, KeyError, TypeError, IndexError):
            message = timeout_message("an FMI call", fmu_path, fmu_timeout())
        print(f"error: {message}", file=sys.stderr)
        return 2
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


def note_fmu(path: object, directory: str | None = None) -> None:
    """Under :func:`supervise`: remember *path* as the FMU whose native code now runs (for the error line).

    With *directory* (where it was extracted), the watchdog can name the FMU of a
    stuck call even when several are open.
    """
    if directory is not None:
        _FMU_DIRS[os.path.realpath(directory)] = str(path)
    target = config.get("supervisor_note")
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
    target = config.get("supervisor_outputs")
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
