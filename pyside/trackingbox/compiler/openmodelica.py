"""The OpenModelica backend: ``omc`` builds an FMI 2.0 FMU (model exchange and co-simulation).

Used where ``omc`` is on PATH (OpenModelica's own installers; it is not in
Debian's or PyPI's packages). The build is one fixed sequence of omc
scripting commands (:func:`build_commands`), sent one by one through a
session object with a ``sendExpression(expr) -> str`` method
(:class:`OmcSession`); after every command ``getErrorString()`` collects omc's
messages, which :mod:`.omc_messages` parses into the embedded path's error
shape (file, line, column, level, message). The sequence:

1. ``cd(<work dir>)``;
2. the FMU options (``setCommandLineOptions``, see :data:`FMU_FLAGS`);
3. ``loadModel(Lib, {"version"})`` for every library the source and the
   ``--library`` packages declare in ``annotation(uses(...))`` (:mod:`.omc_uses`),
   except the libraries given as files;
4. ``loadFile`` of each ``--library`` package, then of the source;
5. ``buildModelFMU(<model>, version="2.0", fmuType="me_cs", ...)``.

:func:`run_build` runs it on any session, so the sequence is tested with a
recording session where omc is absent; :class:`OMPythonSession` is the real
one (OMPython starts ``omc``).
"""
from __future__ import annotations

import logging
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Protocol

from ..errors import CompileError
from ..io import atomic_path
from .omc_interface import ExpectedInterface, compare_interface
from .omc_messages import OmcMessage, compile_error, errors_of, parse_error_string
from .omc_uses import LibraryUse, library_uses, merge_uses, source_uses
from .source import ModelicaSource, read_text, strip_comments

log = logging.getLogger(__name__)

__all__ = ["FMU_FLAGS", "OMPythonSession", "OmcCommand", "OmcSession", "build_commands", "compile_openmodelica",
           "install_hint", "omc_available", "run_build"]

# omc's configuration flags for the FMU, documented in the OpenModelica User's Guide, chapter
# "OpenModelica Compiler Flags" (https://openmodelica.org/doc/OpenModelicaUsersGuide/latest/omchelptext.html)
# and chapter "Functional Mock-up Interface - FMI" (.../latest/fmitlm.html):
# * --fmiFilter=internal: expose every variable of the Modelica model, protected ones included (the
#   default since OpenModelica 1.19 is "protected", which hides them); the embedded path exports
#   every flattened variable, so both FMUs offer the same names. Only the variables omc's symbolic
#   transformations introduce stay hidden.
# * --fmiFlags=s:cvode: the co-simulation interface integrates with CVODE instead of the default
#   explicit Euler at the communication step (model exchange, which trackingbox prefers, is
#   integrated by fmpy's CVode either way).
# Parameters: omc's --evaluateAllParameters (-d=evaluateAllParameters in older releases) turns
# parameters into calculated parameters that an importer cannot set (OpenModelica issue #12056);
# it is off by default and this backend never sets it. OpenModelica's FMI 2 export marks the
# parameters it keeps as variability "fixed" (settable before initialisation, which estimate
# uses); whether a build offers them as "tunable" (pair and track change them between steps) is
# checked after the build (compare_interface) and written in the log.
FMU_FLAGS: tuple[str, ...] = ("--fmiFilter=internal", "--fmiFlags=s:cvode")


def omc_available() -> bool:
    """True when an ``omc`` executable is on PATH (or named by ``OPENMODELICAHOME``)."""
    if shutil.which("omc"):
        return True
    home = os.environ.get("OPENMODELICAHOME")
    return bool(home and (Path(home) / "bin" / "omc").exists())


class OmcSession(Protocol):
    """What the build needs of an omc session: send one scripting expression, get omc's reply
    as text (``true``, ``false``, ``"a string"``), and close."""

    def sendExpression(self, expr: str) -> str: ...  # noqa: N802 - OMPython's name

    def close(self) -> None: ...


Check = Literal["true", "path", "fmu"]


@dataclass(frozen=True)
class OmcCommand:
    """One scripting command of the build.

    Attributes
    ----------
    expr:
        The expression sent to omc.
    step:
        What it does, for errors (``load library Modelica 4.0.0``).
    check:
        How its reply is judged: ``"true"`` (a Boolean that must be true),
        ``"path"`` (a non-empty string, e.g. ``cd``) or ``"fmu"`` (``buildModelFMU``:
        success means the FMU file exists).
    use:
        For ``loadModel``: the use it loads (for the install hint).
    """

    expr: str
    step: str
    check: Check = "true"
    use: LibraryUse | None = None


def _string(value: str | Path) -> str:
    """A Modelica string literal (paths with forward slashes)."""
    text = value.as_posix() if isinstance(value, Path) else value
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _library_file(lib: Path) -> Path:
    return lib / "package.mo" if lib.is_dir() else lib


def _top_name(path: Path) -> str:
    """Top-level class name a package directory or file provides (directory or file stem)."""
    if path.is_dir():
        return path.name
    if path.name == "package.mo":
        return path.parent.name
    try:  # a single file: the first class it declares
        first = re.search(r"\b(?:model|block|class|package|connector|record|function|type)\s+([A-Za-z_]\w*)",
                          strip_comments(read_text(path)))
    except OSError:
        first = None
    return first.group(1) if first else path.stem


def fmu_prefix(model: str) -> str:
    """omc's ``fileNamePrefix`` (the FMU's model identifier) for *model*: a C identifier."""
    return re.sub(r"\W", "_", model)


def build_commands(source: ModelicaSource, model: str, workdir: Path, libraries: tuple[Path, ...] = ()
                   ) -> tuple[OmcCommand, ...]:
    """The omc commands that build *model* from *source* in *workdir*.

    Raises
    ------
    CompileError
        A ``uses`` annotation is malformed, or two uses ask for different
        versions of one library.
    """
    provided = {_top_name(source.entry)}
    provided.update(_top_name(lib) for lib in libraries)
    uses: list[LibraryUse] = []
    for lib in libraries:
        uses.extend(library_uses(lib))
    uses.extend(source_uses(source.entry))
    commands = [OmcCommand(f"cd({_string(workdir)})", f"change directory to {workdir}", "path")]
    commands += [OmcCommand(f"setCommandLineOptions({_string(flag)})", f"set the option {flag}")
                 for flag in FMU_FLAGS]
    for use in merge_uses(uses, provided):
        version = f", {{{_string(use.version)}}}" if use.version else ""
        label = f"{use.name} {use.version}" if use.version else use.name
        commands.append(OmcCommand(f"loadModel({use.name}{version})", f"load library {label}", use=use))
    for lib in libraries:
        commands.append(OmcCommand(f"loadFile({_string(_library_file(lib))})", f"load {_library_file(lib)}"))
    commands.append(OmcCommand(f"loadFile({_string(source.entry)})", f"load {source.entry}"))
    commands.append(OmcCommand(
        f'buildModelFMU({model}, version="2.0", fmuType="me_cs", fileNamePrefix={_string(fmu_prefix(model))}, '
        f'platforms={{"static"}})', f"build an FMU of {model}", "fmu"))
    return tuple(commands)


def install_hint(use: LibraryUse) -> str:
    """How to install the library a ``uses`` entry names, for OpenModelica."""
    version = use.version or "<version>"
    apt = f"omlib-{use.name.lower()}-{version}"
    return (f"\n  library {use.name}{' ' + use.version if use.version else ''} (used at {use.where}) is not "
            f"installed for OpenModelica: install it with OpenModelica's package manager, "
            f"`installPackage({use.name}, \"{version}\")` in omc or OMEdit's File > Manage Libraries > "
            f"Install Library, or on Debian/Ubuntu from OpenModelica's apt repository "
            f"(`apt install {apt}`), or put the library on OPENMODELICALIBRARY")


def _unquote(reply: str) -> str:
    s = str(reply).strip()
    if len(s) >= 2 and s[0] == '"' and s[-1] == '"':
        return s[1:-1].replace('\\"', '"').replace("\\\\", "\\")
    return s


def run_build(session: OmcSession, commands: tuple[OmcCommand, ...], model: str, entry: Path,
              workdir: Path) -> tuple[Path, list[OmcMessage]]:
    """Send *commands* in order, each followed by ``getErrorString()``; stop at the first failure.

    Returns
    -------
    (fmu, messages)
        The FMU omc wrote (in *workdir*) and every message omc gave.

    Raises
    ------
    CompileError
        A command failed: the step, omc's messages as ``file:line:col: level: message``
        lines, and for a library that does not load, how to install it.
    """
    messages: list[OmcMessage] = []
    for command in commands:
        log.debug("omc: %s", command.expr)
        reply = session.sendExpression(command.expr)
        said = parse_error_string(session.sendExpression("getErrorString()"))
        messages.extend(said)
        value = _unquote(reply)
        if command.check == "fmu":
            fmu = workdir / f"{fmu_prefix(model)}.fmu"
            if not fmu.is_file() and value and Path(value).is_file():
                fmu = Path(value)
            if not fmu.is_file():
                raise compile_error(model, entry, command.step, said)
            for m in errors_of(said):
                log.warning("omc reported an error but wrote the FMU: %s", m)
            return fmu, messages
        failed = (value.lower() != "true") if command.check == "true" else not value
        if failed or errors_of(said):
            hint = install_hint(command.use) if command.use is not None else ""
            raise compile_error(model, entry, command.step, said, hint)
    raise CompileError(f"the omc command sequence for {model!r} has no buildModelFMU step")  # pragma: no cover


_OMPYTHON_LOG = re.compile(r"\[(?P<kind>\w+):(?P<level>\w+):\d+\] \[(?P<file>.*?):(?P<ro>\w+):(?P<l1>\d+):"
                           r"(?P<c1>\d+):(?P<l2>\d+):(?P<c2>\d+)\] (?P<msg>.*?)(?=\n\d+: \[|\Z)", re.S)


def ompython_log_to_error_string(text: str) -> str:
    """Rewrite the message list of OMPython 4's session exception
    (``NN: [kind:level:id] [file:readonly:l1:c1:l2:c2] message``) in ``getErrorString()``'s format."""
    out: list[str] = []
    for m in _OMPYTHON_LOG.finditer(text):
        level = {"error": "Error", "warning": "Warning", "notification": "Notification"}.get(
            m.group("level").lower(), "Internal error")
        rw = "readonly" if m.group("ro").lower() in ("true", "readonly") else "writable"
        pos = (f"[{m.group('file')}:{m.group('l1')}:{m.group('c1')}-{m.group('l2')}:{m.group('c2')}:{rw}] "
               if m.group("file") else "")
        out.append(f"{pos}{level}: {m.group('msg').strip()}")
    return "\n".join(out) if out else text.strip()


class OMPythonSession:
    """An omc session through OMPython (``OMCSessionLocal`` of OMPython 4, else ``OMCSessionZMQ``).

    OMPython 4 reads omc's messages itself after every command and raises on an
    error; this adapter keeps those messages and hands them out on the next
    ``getErrorString()``, so :func:`run_build` sees omc's messages with either
    OMPython generation.
    """

    def __init__(self) -> None:
        try:
            import OMPython
        except ImportError as exc:  # pragma: no cover - OMPython is a dependency
            raise CompileError(f"OMPython is not importable: {exc}") from None
        factory = getattr(OMPython, "OMCSessionLocal", None) or OMPython.OMCSessionZMQ
        try:
            self._omc = factory()
        except Exception as exc:  # noqa: BLE001 - omc failed to start: one clear error
            raise CompileError(f"could not start omc through OMPython: {type(exc).__name__}: {exc}") from None
        self._pending: list[str] = []

    def sendExpression(self, expr: str) -> str:  # noqa: N802 - OMPython's name
        try:
            reply = self._omc.sendExpression(expr, False)
        except Exception as exc:  # noqa: BLE001 - OMPython 4 raises on omc's error messages
            self._pending.append(ompython_log_to_error_string(str(exc)))
            return ""
        if expr == "getErrorString()":
            pending, self._pending = self._pending, []
            return "\n".join([*pending, _unquote(reply)])
        return str(reply)

    def close(self) -> None:
        try:
            self._omc.sendExpression("quit()", False)
        except Exception:  # noqa: BLE001 - session teardown
            pass


def compile_openmodelica(source: ModelicaSource, model: str, output: Path,
                         libraries: tuple[Path, ...] = (), *, session: OmcSession | None = None,
                         expected: ExpectedInterface | None = None) -> tuple[str, int, int]:
    """Compile with omc; returns (log, n_states, n_tunable_or_fixed_Real_parameters).

    Parameters
    ----------
    source, model, output, libraries:
        As :func:`trackingbox.compiler.compile_model`.
    session:
        The omc session (default: a new :class:`OMPythonSession`, closed after the build).
    expected:
        Names the FMU must expose (e.g. ``ExpectedInterface.from_spec(spec)``):
        a difference in name, causality or type is a :class:`CompileError` naming
        each variable, and no FMU is written. Parameters that are not tunable are
        written in the log.
    """
    own = session is None
    if own and not omc_available():
        raise CompileError("the openmodelica backend needs omc on PATH; it is not installed here "
                           "(install OpenModelica, see docs/openmodelica.md, or use --backend embedded)")
    with tempfile.TemporaryDirectory(prefix="tbx-omc-") as tmp:
        workdir = Path(tmp)
        commands = build_commands(source, model, workdir, libraries)
        session = OMPythonSession() if own else session
        try:
            built, messages = run_build(session, commands, model, source.entry, workdir)
        finally:
            if own:
                session.close()
        notes = [str(m) for m in messages if m.level != "notification"]
        if expected is not None:
            compare_interface(built, expected, require_tunable=False).raise_for_problems(
                f"the OpenModelica FMU of {model}")
            fixed = compare_interface(built, ExpectedInterface(parameters=expected.parameters))
            notes += [str(p) for p in fixed.problems]
        output.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(output) as part:
            shutil.copyfile(built, part)
    from fmpy import read_model_description

    md = read_model_description(str(output))
    states = len(md.derivatives)
    params = sum(1 for v in md.modelVariables if v.causality == "parameter" and v.type in ("Real", "Float64"))
    tunable = sum(1 for v in md.modelVariables if v.causality == "parameter" and v.variability == "tunable")
    summary = (f"{model}: OpenModelica FMI {md.fmiVersion} FMU, {states} states, {params} Real parameters "
               f"({tunable} tunable)")
    log.info(summary)
    return "\n".join([summary, *notes]), states, params
