"""The FMU layer: read an FMU's interface, simulate it, step it in time.

A thin wrapper around FMPy. The model description is FMPy's
:class:`fmpy.model_description.ModelDescription`; this module only adds

* :func:`read_info`: the variables of an FMU as small frozen records, with
  errors that name the file and the problem (:class:`~trackingbox.errors.FMUError`);
* :class:`FMUModel`: extract and instantiate an FMU *once* and run it many
  times (``reset`` between runs, never re-extract);
* :class:`Stepper`: advance one communication step at a time and change tunable
  parameters and inputs between steps, as the tracking loop does.

Layout: :class:`FMUModel` owns the FMU instance and hands each run a driver
behind the one :class:`Stepper` interface, :class:`ModelExchangeStepper` or
:class:`CoSimulationStepper`; the two talk only through public methods
(``FMUModel.variable``, ``begin_run``, ``note_changed``; ``Stepper.finish``,
``input_times``, ``reader``). What differs between FMI 2 and FMI 3 (typed
Real access, initialisation, event iteration, derivative call, termination
flags) sits in the thin adapters ``_FMI2``/``_FMI3``. A failure reported by
the FMU or the solver becomes a :class:`~trackingbox.errors.SimulationError`
in one place, :func:`_simulation_failure`.

Model exchange FMUs (FMI 2 and FMI 3) are integrated with CVODE (BDF, dense
direct solver) from FMPy's bundled SUNDIALS; after every parameter change,
input override or state overwrite the integrator is re-initialised, because such
a change is a discontinuity. Co-simulation FMUs (FMI 2 and FMI 3) are advanced
with ``doStep``.
"""
from __future__ import annotations

import abc
import collections
import contextlib
import ctypes
import logging
import math
import os
import re
import shutil
import weakref
import zipfile
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import fmpy
import numpy as np
import numpy.typing as npt
import pandas as pd
from fmpy.model_description import ModelDescription, ModelVariable

from .errors import AssertionFailed, DataError, FMUError, SimulationError, unknown_name

log = logging.getLogger(__name__)

Interface = Literal["ModelExchange", "CoSimulation"]

_REAL_TYPES = frozenset({"Real", "Float64", "Float32"})
_NUMERIC_TYPES = _REAL_TYPES | frozenset(
    {"Integer", "Enumeration", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}
)


# ---------------------------------------------------------------------------
# read_info
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Variable:
    """One model variable of an FMU, in FMI's words.

    ``start``, ``min``, ``max`` and ``nominal`` are floats for numeric variables
    (``bool`` for Boolean, ``str`` for String starts), ``None`` where the model
    description does not give them. ``unit`` comes from the variable or, when it
    has none, from its declared type (FMI 2 puts units on type definitions).
    """

    name: str
    causality: str
    variability: str
    type: str
    start: float | bool | str | None
    min: float | None
    max: float | None
    nominal: float | None
    unit: str | None
    description: str | None
    value_reference: int


@dataclass(frozen=True)
class FMUInfo:
    """What an FMU offers: FMI version, interfaces, variables, default experiment."""

    path: Path
    fmi_version: str
    model_name: str
    interfaces: tuple[str, ...]
    variables: tuple[Variable, ...]
    start_time: float | None = None
    stop_time: float | None = None
    tolerance: float | None = None
    step_size: float | None = None
    number_of_states: int = 0
    model_description: ModelDescription | None = field(default=None, repr=False, compare=False)

    def variable(self, name: str) -> Variable:
        """Return the variable called *name*; :class:`FMUError` with a did-you-mean otherwise."""
        for v in self.variables:
            if v.name == name:
                return v
        raise FMUError(unknown_name("variable", name, self.names(), self.path.name))

    def names(self, causality: str | None = None, variability: str | None = None) -> list[str]:
        """Names of the variables, optionally filtered by causality and variability."""
        return [
            v.name for v in self.variables
            if (causality is None or v.causality == causality)
            and (variability is None or v.variability == variability)
        ]

    @property
    def inputs(self) -> list[str]:
        """Names of the FMU's inputs."""
        return self.names("input")

    @property
    def outputs(self) -> list[str]:
        """Names of the FMU's outputs."""
        return self.names("output")

    @property
    def tunable_parameters(self) -> list[str]:
        """Names of the parameters that may change during a simulation."""
        return self.names("parameter", "tunable")


def _float_or_none(text: Any) -> float | None:
    if text is None:
        return None
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def _start_value(v: ModelVariable) -> float | bool | str | None:
    if v.start is None:
        return None
    if v.type == "Boolean":
        return str(v.start).strip().lower() in {"true", "1"}
    if v.type in _NUMERIC_TYPES:
        value = _float_or_none(v.start)
        return value if value is not None else str(v.start)
    return str(v.start)


def _attr(v: ModelVariable, name: str) -> Any:
    value = getattr(v, name, None)
    if value is None and v.declaredType is not None:
        value = getattr(v.declaredType, name, None)
    return value


def _to_variable(v: ModelVariable) -> Variable:
    return Variable(
        name=v.name,
        causality=v.causality or "local",
        variability=v.variability or "continuous",
        type=v.type,
        start=_start_value(v),
        min=_float_or_none(_attr(v, "min")),
        max=_float_or_none(_attr(v, "max")),
        nominal=_float_or_none(_attr(v, "nominal")),
        unit=_attr(v, "unit"),
        description=v.description,
        value_reference=int(v.valueReference) if v.valueReference is not None else -1,
    )


def _read_model_description(path: Path) -> ModelDescription:
    """Read (and, where possible, validate) the model description of *path*."""
    from fmpy.model_description import ValidationError, read_model_description

    if not path.exists():
        raise FMUError(f"FMU {path} does not exist")
    if path.is_dir():
        raise FMUError(f"FMU {path} is a directory, not an .fmu file")
    if not zipfile.is_zipfile(path):
        raise FMUError(f"FMU {path} is not a valid FMU: it is not a ZIP archive")
    entries = _zip_entry_count(path)
    if entries is not None and entries > MAX_ENTRIES:
        # refused before zipfile parses the directory: 100,000 entries take seconds to list
        raise FMUError(f"FMU {path} has {entries} archive entries (at most {MAX_ENTRIES}): not read")
    try:
        with zipfile.ZipFile(path) as zf:
            names = set(zf.namelist())
            described = zf.getinfo("modelDescription.xml").file_size if "modelDescription.xml" in names else 0
    except (OSError, zipfile.BadZipFile, EOFError, ValueError) as exc:
        raise FMUError(f"FMU {path} cannot be read: {str(exc)[:200]}") from None
    if "modelDescription.xml" not in names:
        raise FMUError(f"FMU {path} is not a valid FMU: it has no modelDescription.xml")
    if described > MAX_DESCRIPTION_BYTES:
        raise FMUError(f"FMU {path} has a modelDescription.xml of {described / 2**20:.0f} MiB "
                       f"(at most {MAX_DESCRIPTION_BYTES / 2**20:.0f} MiB): not read")
    try:
        return read_model_description(str(path), validate=True)
    except ValidationError as exc:
        problems = "; ".join(str(p) for p in exc.problems[:5])
        log.warning("%s: modelDescription.xml does not validate (%s); reading it without validation",
                    path, problems)
    except Exception as exc:  # malformed XML, unsupported version, ...
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise FMUError(f"FMU {path} has an invalid modelDescription.xml: {first}") from None
    try:
        return read_model_description(str(path), validate=False)
    except Exception as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise FMUError(f"FMU {path} has an invalid modelDescription.xml: {first}") from None


def read_info(path: str | Path) -> FMUInfo:
    """Read the interface of the FMU at *path* without extracting or loading it.

    Parameters
    ----------
    path
        An ``.fmu`` file (FMI 2.0 or 3.0).

    Returns
    -------
    FMUInfo
        FMI version, model name, interfaces and variables.

    Raises
    ------
    FMUError
        The file is missing, not a ZIP archive, has no ``modelDescription.xml``
        or an invalid one.
    """
    path = Path(path)
    md = _read_model_description(path)
    seen: set[str] = set()
    for v in md.modelVariables:
        if v.name in seen:
            raise FMUError(f"FMU {path} has an invalid modelDescription.xml: variable {v.name[:80]!r} "
                           "is declared twice")
        seen.add(v.name)
    interfaces = tuple(
        name for name, present in (("ModelExchange", md.modelExchange), ("CoSimulation", md.coSimulation))
        if present is not None
    )
    exp = md.defaultExperiment
    return FMUInfo(
        path=path,
        fmi_version=str(md.fmiVersion),
        model_name=str(md.modelName),
        interfaces=interfaces,
        variables=tuple(_to_variable(v) for v in md.modelVariables),
        start_time=_float_or_none(exp.startTime) if exp else None,
        stop_time=_float_or_none(exp.stopTime) if exp else None,
        tolerance=_float_or_none(exp.tolerance) if exp else None,
        step_size=_float_or_none(exp.stepSize) if exp else None,
        number_of_states=int(md.numberOfContinuousStates or 0),
        model_description=md,
    )


# ---------------------------------------------------------------------------
# error translation
# ---------------------------------------------------------------------------

Messages = collections.deque  # (status, category, text) logged by an FMU, newest last

_ASSERT_LOG = re.compile(r"assert failed at t = (\S+) s: (.*)", re.S)


def _fmi3_logger(name: str, messages: Messages) -> Any:
    """An FMI 3 log callback: keeps (status, category, message) and logs to Python logging."""

    def log_message(env: Any, status: int, category: bytes | None, message: bytes | None) -> None:
        text = (message or b"").decode("utf-8", errors="replace")
        cat = (category or b"").decode("utf-8", errors="replace")
        messages.append((int(status), cat, text))
        # errors become exceptions (and the CLI's error line); log them only for -vv
        level = logging.DEBUG if status >= 3 or status == 0 else logging.WARNING
        log.log(level, "%s: %s", name, text)

    return log_message


def _simulation_failure(what: str, cause: object, messages: Messages | None = None, *,
                        solver: bool = False) -> SimulationError:
    """The one place where a failure reported by an FMU or the solver becomes a :class:`SimulationError`.

    *what* says what failed, naming the FMU and the time (``"simulation of
    twin.fmu failed at t = 12 s"``); *cause* is the exception (or solver message)
    that reported it; *messages* are what the FMU logged (FMI 3). A failed
    ``assert`` the FMU logged becomes :class:`AssertionFailed` with the model's
    message and time; otherwise the FMU's last logged error is added to the text.
    With *solver* (the integrator failed), an assert the FMU saw failing at a
    trial point of the failed step (category ``assert-trial``) is the cause.
    Every driver below raises through this function.
    """
    for status, category, text in reversed(messages or ()):
        if solver and category == "assert-trial":
            found = _ASSERT_LOG.match(text)
            if found:
                return AssertionFailed(found.group(2), float(found.group(1)), _fmu_name(what))
        if status < 3:
            continue
        found = _ASSERT_LOG.match(text)
        if found:
            return AssertionFailed(found.group(2), float(found.group(1)), _fmu_name(what))
        return SimulationError(f"{what}: {cause}: {text}")
    return SimulationError(f"{what}: {cause}")


def _fmu_name(what: str) -> str:
    found = re.search(r"(\S+\.fmu)", what)
    return found.group(1) if found else "the FMU"


@contextlib.contextmanager
def _fmu_calls(what: str, messages: Messages | None = None) -> Iterator[None]:
    """Translate any exception of the FMU calls in the body (ours pass unchanged); see :func:`_simulation_failure`."""
    try:
        yield
    except (FMUError, SimulationError):
        raise
    except Exception as exc:
        raise _simulation_failure(what, exc, messages) from None


# ---------------------------------------------------------------------------
# FMI 2 / FMI 3 adapters
# ---------------------------------------------------------------------------

class _FMI(abc.ABC):
    """What differs between FMI 2 and FMI 3 for the drivers, on one FMPy instance.

    Everything else (``reset``, ``setTime``, ``doStep``, the continuous-state
    calls, the typed ``get*``/``set*``) has the same name in FMPy's FMI 2 and
    FMI 3 classes and is called on :attr:`instance` directly.
    """

    #: FMI type name under which an enumeration is read and written.
    enumeration_type = "Integer"

    def __init__(self, instance: Any, model_description: ModelDescription) -> None:
        self.instance = instance
        self.model_description = model_description

    @abc.abstractmethod
    def real_reader(self, value_references: Sequence[int]) -> Callable[[], npt.NDArray[np.float64]]:
        """A fast reader of these Real/Float64 variables (one C call, values copied)."""

    @abc.abstractmethod
    def real_writer(self, value_references: Sequence[int]) -> Callable[[Any], None]:
        """A fast writer of these Real/Float64 variables (one C call)."""

    @abc.abstractmethod
    def enter_initialization_mode(self, *, tolerance: float, start_time: float) -> None:
        """Enter initialisation mode with the run's tolerance and start time."""

    @abc.abstractmethod
    def update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        """One event-iteration call: ``(needed, terminate, next_event_defined, next_event_time)``."""

    @property
    @abc.abstractmethod
    def get_derivatives(self) -> Callable[..., Any]:
        """FMPy's call filling the state-derivative vector (model exchange)."""

    @abc.abstractmethod
    def needs_completed_integrator_step(self) -> bool:
        """Whether ``completedIntegratorStep`` must be called after each solver step (model exchange)."""

    def terminated(self, do_step_result: Any) -> bool:
        """Whether a ``doStep`` result says the FMU asked to terminate (co-simulation)."""
        return False

    @abc.abstractmethod
    def directional(self, unknowns: Sequence[int], knowns: Sequence[int]
                    ) -> Callable[[Any], npt.NDArray[np.float64]]:
        """A fast ``seed -> sensitivity`` of the FMU's directional derivative (one C call, values copied).

        ``sensitivity = (d unknowns / d knowns) @ seed`` at the current point.
        """


def _buffer(value_references: Sequence[int]) -> tuple[int, Any, npt.NDArray[np.float64], Any]:
    n = len(value_references)
    vr = (ctypes.c_uint32 * n)(*value_references)
    buf = np.zeros(n)
    return n, vr, buf, buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


class _FMI2(_FMI):
    enumeration_type = "Integer"

    def real_reader(self, value_references: Sequence[int]) -> Callable[[], npt.NDArray[np.float64]]:
        n, vr, buf, pbuf = _buffer(value_references)
        func, comp = self.instance.fmi2GetReal, self.instance.component

        def read() -> npt.NDArray[np.float64]:
            func(comp, vr, n, pbuf)
            return buf.copy()
        return read

    def real_writer(self, value_references: Sequence[int]) -> Callable[[Any], None]:
        n, vr, buf, pbuf = _buffer(value_references)
        func, comp = self.instance.fmi2SetReal, self.instance.component

        def write(values: Any) -> None:
            buf[:] = values
            func(comp, vr, n, pbuf)
        return write

    def enter_initialization_mode(self, *, tolerance: float, start_time: float) -> None:
        self.instance.setupExperiment(tolerance=tolerance, startTime=start_time)
        self.instance.enterInitializationMode()

    def update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        needed, terminate, _, _, next_defined, next_time = self.instance.newDiscreteStates()
        return needed, terminate, next_defined, next_time

    @property
    def get_derivatives(self) -> Callable[..., Any]:
        return self.instance.getDerivatives

    def needs_completed_integrator_step(self) -> bool:
        # FMI 2 asks for the call with needsCompletedIntegratorStep
        return bool(self.model_description.modelExchange.needsCompletedIntegratorStep)

    def directional(self, unknowns: Sequence[int], knowns: Sequence[int]
                    ) -> Callable[[Any], npt.NDArray[np.float64]]:
        nu, vu, out, pout = _buffer(unknowns)
        nk, vk, seed, pseed = _buffer(knowns)
        func, comp = self.instance.fmi2GetDirectionalDerivative, self.instance.component

        def call(values: Any) -> npt.NDArray[np.float64]:
            seed[:] = values
            func(comp, vu, nu, vk, nk, pseed, pout)
            return out.copy()
        return call


class _FMI3(_FMI):
    enumeration_type = "Int64"

    def real_reader(self, value_references: Sequence[int]) -> Callable[[], npt.NDArray[np.float64]]:
        n, vr, buf, pbuf = _buffer(value_references)
        func, comp = self.instance.fmi3GetFloat64, self.instance.component

        def read() -> npt.NDArray[np.float64]:
            func(comp, vr, n, pbuf, n)
            return buf.copy()
        return read

    def real_writer(self, value_references: Sequence[int]) -> Callable[[Any], None]:
        n, vr, buf, pbuf = _buffer(value_references)
        func, comp = self.instance.fmi3SetFloat64, self.instance.component

        def write(values: Any) -> None:
            buf[:] = values
            func(comp, vr, n, pbuf, n)
        return write

    def enter_initialization_mode(self, *, tolerance: float, start_time: float) -> None:
        self.instance.enterInitializationMode(tolerance=tolerance, startTime=start_time)

    def update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        needed, terminate, _, _, next_defined, next_time = self.instance.updateDiscreteStates()
        return needed, terminate, next_defined, next_time

    @property
    def get_derivatives(self) -> Callable[..., Any]:
        return self.instance.getContinuousStateDerivatives

    def needs_completed_integrator_step(self) -> bool:
        # FMI 3 waives the call with completedIntegratorStepNotNeeded
        return not self.model_description.modelExchange.completedIntegratorStepNotNeeded

    def terminated(self, do_step_result: Any) -> bool:
        return do_step_result is not None and bool(do_step_result[1])

    def directional(self, unknowns: Sequence[int], knowns: Sequence[int]
                    ) -> Callable[[Any], npt.NDArray[np.float64]]:
        nu, vu, out, pout = _buffer(unknowns)
        nk, vk, seed, pseed = _buffer(knowns)
        func, comp = self.instance.fmi3GetDirectionalDerivative, self.instance.component

        def call(values: Any) -> npt.NDArray[np.float64]:
            seed[:] = values
            func(comp, vu, nu, vk, nk, pseed, nk, pout, nu)
            return out.copy()
        return call


# ---------------------------------------------------------------------------
# bounded extraction and the canary (foreign native code isolated)
# ---------------------------------------------------------------------------

#: most entries an FMU archive may have
MAX_ENTRIES = 20_000
#: most bytes an FMU may inflate to (``TRACKINGBOX_FMU_MAX_BYTES`` overrides)
MAX_EXTRACTED_BYTES = 2 << 30
#: largest modelDescription.xml read (bytes)
MAX_DESCRIPTION_BYTES = 200 << 20


def _zip_entry_count(path: Path) -> int | None:
    """The number of entries a ZIP archive's end record declares (ZIP64 too), or None if it cannot be read."""
    import struct

    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(0, size - (1 << 16) - 22))
            tail = fh.read()
            at = tail.rfind(b"PK\x05\x06")
            if at < 0 or len(tail) < at + 22:
                return None
            count = struct.unpack("<H", tail[at + 10:at + 12])[0]
            locator = tail.rfind(b"PK\x06\x07", 0, at)
            if count == 0xFFFF and locator >= 0:
                offset = struct.unpack("<Q", tail[locator + 8:locator + 16])[0]
                fh.seek(offset)
                record = fh.read(56)
                if record[:4] == b"PK\x06\x06":
                    count = struct.unpack("<Q", record[32:40])[0]
            return int(count)
    except (OSError, struct.error):
        return None


def _max_bytes() -> int:
    try:
        return int(os.environ.get("TRACKINGBOX_FMU_MAX_BYTES", MAX_EXTRACTED_BYTES))
    except ValueError:
        return MAX_EXTRACTED_BYTES


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


def _extract(path: Path) -> str:
    """Extract *path* to a new temporary directory, bounded in entries and bytes; nothing left on failure.

    The sizes the archive declares are checked first; while inflating, the bytes
    actually written are counted too (a forged header cannot get past the limit).
    """
    import tempfile

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
        from .supervise import note_output

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
CANARY_TIMEOUT = 60.0
_CANARY_PASSED: set[tuple[Any, ...]] = set()


def _canary_timeout() -> float:
    from .supervise import fmu_timeout

    return fmu_timeout()


def _canary_calls(tempdir: str, md: ModelDescription, interface: str,
                  phase: Callable[[str], None]) -> None:
    """In the canary process: load, instantiate, initialise, read the outputs, take one step, free."""
    v3 = str(md.fmiVersion).startswith("3")
    p = "fmi3" if v3 else "fmi2"
    if v3:
        from fmpy.fmi3 import FMU3Model as Model, FMU3Slave as Slave
    else:
        from fmpy.fmi2 import FMU2Model as Model, FMU2Slave as Slave  # type: ignore[assignment]
    kind = md.coSimulation if interface == "CoSimulation" else md.modelExchange
    cls = Slave if interface == "CoSimulation" else Model
    phase("the loading of its shared library")
    fmu = cls(guid=md.guid, unzipDirectory=tempdir, modelIdentifier=kind.modelIdentifier,
              instanceName="canary")
    phase(f"{p}Instantiate")
    fmu.instantiate()
    exp = md.defaultExperiment
    t0 = _float_or_none(exp.startTime) if exp else None
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
        step = (_float_or_none(exp.stepSize) if exp else None) or 1e-3
        phase(f"{p}DoStep")
        fmu.doStep(currentCommunicationPoint=t0, communicationStepSize=step)
        if reals:
            phase(f"{p}GetFloat64" if v3 else "fmi2GetReal")
            (fmu.getFloat64 if v3 else fmu.getReal)(reals)
    phase(f"{p}Terminate")
    fmu.terminate()
    phase(f"{p}FreeInstance")
    fmu.freeInstance()


def _canary(path: Path, tempdir: str, md: ModelDescription, interface: str) -> None:
    """Run the FMU's native code once in a forked process before this process loads it.

    A crash (signal), a call to ``exit()`` or a call that does not return within
    ``TRACKINGBOX_FMU_TIMEOUT`` seconds in loading, instantiation, initialisation,
    the first output read or the first step becomes an :class:`FMUError` naming
    the signal and the FMI function. Checked once per file (path, size, mtime) and
    interface in a process. An FMI call that merely reports an error is left to
    the normal path, which reports it with the FMU's own message.
    ``TRACKINGBOX_CANARY=0`` skips it (a trusted FMU; benchmarks of its cost).
    """
    import select
    import signal
    import time

    try:
        st = path.stat()
        key: tuple[Any, ...] = (str(path.resolve()), st.st_size, st.st_mtime_ns, interface)
    except OSError:
        key = (str(path), interface)
    if key in _CANARY_PASSED or not hasattr(os, "fork") or os.environ.get("TRACKINGBOX_CANARY", "1") == "0":
        return
    timeout = _canary_timeout()
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child: report each phase, then the end, and leave
        code = 0
        try:
            os.close(read_fd)
            import faulthandler

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


def check_values(info: FMUInfo, values: Mapping[str, float], where: str) -> None:
    """Refuse values outside the min/max the FMU declares for the variable (every problem at once).

    >>> v = Variable("k", "parameter", "tunable", "Real", 1.0, 0.0, 2.0, None, None, "", 1)
    >>> info = FMUInfo(Path("t.fmu"), "3.0", "M", ("ModelExchange",), (v,))
    >>> check_values(info, {"k": 3.0}, "--set")
    Traceback (most recent call last):
    ...
    trackingbox.errors.FMUError: --set: k = 3 is outside [0, 2] that t.fmu declares
    """
    problems = []
    for name, value in values.items():
        try:
            v = info.variable(name)
        except FMUError:
            continue
        lo = _float_or_none(v.min)
        hi = _float_or_none(v.max)
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            problems.append(f"{name} = {value:g} is outside [{'-inf' if lo is None else f'{lo:g}'}, "
                            f"{'inf' if hi is None else f'{hi:g}'}] that {info.path.name} declares")
    if problems:
        raise FMUError(f"{where}: " + "; ".join(problems))


# ---------------------------------------------------------------------------
# FMUModel
# ---------------------------------------------------------------------------

def _cleanup(holder: dict[str, Any], tempdir: str | None, pid: int) -> None:
    """Free the FMU instance and delete the extraction directory (also run at GC).

    Only in the process that opened the FMU: a forked worker that drops an
    inherited :class:`FMUModel` must not delete its parent's files.
    """
    if os.getpid() != pid:
        holder.pop("fmu", None)
        return
    fmu = holder.pop("fmu", None)
    if fmu is not None:
        with contextlib.suppress(Exception):
            fmu.freeInstance()
    if tempdir:
        shutil.rmtree(tempdir, ignore_errors=True)
        from .supervise import note_output

        note_output(tempdir, False)


class FMUModel:
    """An FMU extracted and instantiated once, simulated many times.

    Parameters
    ----------
    path
        The ``.fmu`` file.
    tolerance
        Relative tolerance of the ODE solver (model exchange) and the value
        passed to the FMU at initialisation.
    interface
        ``"ModelExchange"`` or ``"CoSimulation"``; default: model exchange
        when the FMU offers it (we then control the solver), else co-simulation.

    Examples
    --------
    Run one FMU for several parameter values (it is extracted once)::

        with FMUModel("twin.fmu") as model:
            for k in (800.0, 1000.0):
                df = model.simulate(stop_time=3600, output_interval=10, parameters={"hx.kht": k})
    """

    def __init__(self, path: str | Path, *, tolerance: float = 1e-6, interface: Interface | None = None):
        self.path = Path(path)
        self.info = read_info(self.path)
        self.tolerance = float(tolerance)
        md = self.info.model_description
        assert md is not None
        if interface is None:
            interface = "ModelExchange" if md.modelExchange is not None else "CoSimulation"
        if interface not in self.info.interfaces:
            raise FMUError(
                f"FMU {self.path} does not provide the {interface} interface "
                f"(it provides: {', '.join(self.info.interfaces) or 'none'})"
            )
        self.interface: Interface = interface
        if self.info.fmi_version.startswith("1"):
            raise FMUError(f"FMU {self.path} is FMI {self.info.fmi_version}; only FMI 2.0 and 3.0 are supported")

        platforms = fmpy.supported_platforms(str(self.path))
        if fmpy.platform not in platforms and fmpy.platform_tuple not in platforms:
            raise FMUError(
                f"FMU {self.path} has no binary for this platform ({fmpy.platform_tuple}); "
                f"it has: {', '.join(platforms) or 'none'}"
            )

        self._vars: dict[str, ModelVariable] = {}
        for v in md.modelVariables:
            self._vars.setdefault(v.name, v)
        self._holder: dict[str, Any] = {}
        #: what the FMU logged (FMI 3), newest last: error reports read failed asserts from it
        self.log_messages: Messages = collections.deque(maxlen=20)
        self._tempdir: str | None = None
        from .supervise import note_fmu

        note_fmu(self.path)
        self._tempdir = _extract(self.path)
        note_fmu(self.path, self._tempdir)  # the watchdog names this FMU if one of its calls hangs
        self._finalizer = weakref.finalize(self, _cleanup, self._holder, self._tempdir, os.getpid())
        try:
            _canary(self.path, self._tempdir, md, interface)
        except BaseException:
            self._finalizer()
            raise
        try:
            from fmpy.simulation import instantiate_fmu

            # FMI 3: the FMU's log goes to Python logging and is kept for error reports (asserts)
            logger = (_fmi3_logger(self.path.name, self.log_messages)
                      if self.info.fmi_version.startswith("3") else None)
            fmu = instantiate_fmu(self._tempdir, md, fmi_type=interface, logger=logger)
        except Exception as exc:
            self._finalizer()
            raise FMUError(f"FMU {self.path} could not be loaded and instantiated: {exc}") from None
        self._holder["fmu"] = fmu
        adapter = _FMI3 if self.info.fmi_version.startswith("3") else _FMI2
        self._fmi: _FMI = adapter(fmu, md)
        self._used = False
        self._active: Stepper | None = None
        self._changed: set[str] = set()
        #: why the last model-exchange run is not native (None: it is; see :meth:`stepper`)
        self.native_reason: str | None = None
        log.debug("opened %s (FMI %s, %s) in %s", self.path, self.info.fmi_version, interface, self._tempdir)

    # -- context manager / cleanup ------------------------------------------
    def __enter__(self) -> FMUModel:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Free the FMU instance and delete the extracted files (idempotent)."""
        self._finish_active()
        self._finalizer()

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return not self._finalizer.alive

    def _finish_active(self) -> None:
        if self._active is not None:
            self._active.finish()
            self._active = None

    # -- name resolution ----------------------------------------------------
    def variable(self, name: str, what: str = "variable") -> ModelVariable:
        """FMPy's description of the variable *name*.

        Raises
        ------
        FMUError
            No such variable (with a did-you-mean); *what* names the role in the message.
        """
        try:
            return self._vars[name]
        except KeyError:
            raise FMUError(unknown_name(what, name, self._vars, f"FMU {self.path.name}")) from None

    # -- start values changed by runs -------------------------------------------
    def begin_run(self, parameters: Mapping[str, Any]) -> dict[str, Any]:
        """Start values to restore before a run that sets *parameters*.

        Returns the declared start value of every variable an earlier run changed
        and this run does not set (robust against FMUs whose ``reset`` is
        partial), and records *parameters* as changed by this run.
        """
        restore = [n for n in self._changed if n not in parameters and self._vars[n].start is not None]
        self._changed = set(parameters)
        return {n: _start_value(self._vars[n]) for n in restore}

    def note_changed(self, names: Iterable[str]) -> None:
        """Record that the running run changed the parameters *names* (restored at the next run)."""
        self._changed.update(names)

    # -- runs -----------------------------------------------------------------
    def stepper(
        self,
        *,
        start_time: float = 0.0,
        parameters: Mapping[str, float] | None = None,
        inputs: pd.DataFrame | None = None,
        max_step: float | None = None,
        carry: bool = False,
        native: bool | None = None,
    ) -> Stepper:
        """Initialise a new run at *start_time* and return its :class:`Stepper`.

        Any previous stepper of this model becomes unusable (one FMU instance).
        The stepper is a :class:`ModelExchangeStepper` or a
        :class:`CoSimulationStepper`, after :attr:`interface`.

        Parameters
        ----------
        start_time
            Simulation start time (s).
        parameters
            Values set before initialisation: parameters (fixed or tunable),
            start values of states (``initial="exact"``), or constant inputs.
        inputs
            Table with a ``time`` column (s) and FMU input columns; linear
            interpolation between samples, held constant before the first and
            after the last sample.
        max_step
            Largest internal solver step (model exchange); default: the smallest
            spacing of the input samples (so no input feature is stepped over).
        carry
            Model exchange: stop CVODE exactly at every communication point
            (its stop time) instead of letting it step past and interpolate
            back, so that :meth:`Stepper.set` with ``restart=False`` can carry
            the integrator across a small change (no re-initialisation).
            Without it every change restarts the integrator.
        native
            Model exchange: integrate with :class:`~trackingbox.native.NativeStepper`
            (CVODE and the FMU's right-hand side in C, same settings and
            results). ``None`` (default): where the FMU allows it (event-free
            FMI 3 with states, a C compiler at hand) unless the environment
            variable ``TRACKINGBOX_NATIVE`` is ``0``; otherwise the Python path,
            and the reason is logged at debug level and kept in
            :attr:`native_reason`. ``True``: native or :class:`FMUError` saying
            why not. ``False``: the Python path.
        """
        if self.closed:
            raise FMUError(f"FMU {self.path} is closed")
        self._finish_active()
        if self._used:
            try:
                self._fmi.instance.reset()
            except Exception as exc:
                raise FMUError(f"FMU {self.path}: reset failed: {exc}") from None
        self._used = True
        driver = self._driver(native)
        stepper = driver(self, self._fmi, start_time=float(start_time), parameters=dict(parameters or {}),
                         inputs=inputs, max_step=max_step)
        if carry and isinstance(stepper, ModelExchangeStepper):
            stepper.carry()
        self._active = stepper
        return stepper

    def _driver(self, native: bool | None) -> type[Stepper]:
        """The stepper class for a new run (see :meth:`stepper`'s *native*); sets :attr:`native_reason`."""
        if self.interface != "ModelExchange":
            self.native_reason = f"{self.path.name} runs as co-simulation"
            if native:
                raise FMUError(f"no native stepper for {self.path.name}: {self.native_reason}")
            return CoSimulationStepper
        if native is False:
            self.native_reason = "not asked for (native=False)"
            return ModelExchangeStepper
        if native is None and os.environ.get("TRACKINGBOX_NATIVE", "").strip() == "0":
            self.native_reason = "TRACKINGBOX_NATIVE=0"
        else:
            from .native import NativeStepper, native_reason

            self.native_reason = native_reason(self)
            if self.native_reason is None:
                return NativeStepper
        if native:
            raise FMUError(f"no native stepper for {self.path.name}: {self.native_reason}")
        log.debug("%s: Python model-exchange stepper (%s)", self.path.name, self.native_reason)
        return ModelExchangeStepper

    def sensitivity_stepper(
        self,
        wrt: Sequence[str],
        scales: Sequence[float],
        *,
        start_time: float = 0.0,
        parameters: Mapping[str, float] | None = None,
        inputs: pd.DataFrame | None = None,
        max_step: float | None = None,
    ) -> SensitivityStepper:
        """Initialise a run that also integrates the sensitivities w.r.t. the tunable parameters *wrt*.

        As :meth:`stepper` (model exchange only); *scales* (one positive number
        per parameter, e.g. its bound range) scale the sensitivity equations
        (:class:`SensitivityStepper`). Check :func:`directional_derivatives_reason`
        first: this does not.
        """
        if self.closed:
            raise FMUError(f"FMU {self.path} is closed")
        if self.interface != "ModelExchange":
            raise FMUError(f"FMU {self.path} runs as co-simulation: its states and directional derivatives "
                           "are not accessible")
        self._finish_active()
        if self._used:
            try:
                self._fmi.instance.reset()
            except Exception as exc:
                raise FMUError(f"FMU {self.path}: reset failed: {exc}") from None
        self._used = True
        stepper = SensitivityStepper(self, self._fmi, start_time=float(start_time),
                                     parameters=dict(parameters or {}), inputs=inputs, max_step=max_step,
                                     wrt=wrt, scales=scales)
        self._active = stepper
        return stepper

    def simulate(
        self,
        *,
        start_time: float = 0.0,
        stop_time: float,
        output_interval: float,
        inputs: pd.DataFrame | None = None,
        parameters: Mapping[str, float] | None = None,
        outputs: Sequence[str] | None = None,
    ) -> pd.DataFrame:
        """Simulate from *start_time* to *stop_time* and sample every *output_interval*.

        Built on :class:`Stepper`: the communication points are the output grid
        plus every input sample time inside the interval (so co-simulation FMUs,
        which hold an input over a step, see every input sample).

        Returns
        -------
        pandas.DataFrame
            Column ``time`` then one column per requested variable (default:
            all outputs).

        Raises
        ------
        FMUError
            Unknown variable names (with a did-you-mean).
        SimulationError
            The solver failed or produced non-finite values; names the time.
        """
        start_time = float(start_time)
        stop_time = float(stop_time)
        output_interval = float(output_interval)
        if not (math.isfinite(start_time) and math.isfinite(stop_time)) or stop_time < start_time:
            raise FMUError(f"stop time {stop_time} must not be before start time {start_time}")
        if not (output_interval > 0 and math.isfinite(output_interval)):
            raise FMUError(f"output interval must be a positive number, not {output_interval}")
        names = list(outputs) if outputs is not None else self.info.outputs
        for name in names:
            self.variable(name, "output variable")
        n = int(math.floor((stop_time - start_time) / output_interval + 1e-9))
        grid = start_time + output_interval * np.arange(n + 1)
        if grid[-1] < stop_time - 1e-9 * max(1.0, abs(stop_time)):
            grid = np.append(grid, stop_time)
        points = grid
        stepper = self.stepper(start_time=start_time, parameters=parameters, inputs=inputs)
        input_times = stepper.input_times
        if input_times is not None and input_times.size:
            extra = input_times[(input_times > start_time) & (input_times < stop_time)]
            points = np.union1d(grid, extra)
        record = np.isin(points, grid)
        rows = np.empty((grid.size, len(names)))
        read = stepper.reader(names)
        j = 0
        for t, keep in zip(points, record):
            stepper.step(float(t))
            if keep:
                rows[j] = read()
                j += 1
        bad = ~np.isfinite(rows)
        if bad.any():
            i, c = np.argwhere(bad)[0]
            raise SimulationError(
                f"simulation of {self.path.name} produced a non-finite value of {names[c]!r} "
                f"at t = {grid[i]:g} s"
            )
        df = pd.DataFrame(rows, columns=names)
        df.insert(0, "time", grid)
        return df


# ---------------------------------------------------------------------------
# Stepper: the interface, and one driver per FMI interface
# ---------------------------------------------------------------------------

class Stepper(abc.ABC):
    """One run of an FMU, advanced communication step by communication step.

    Create with :meth:`FMUModel.stepper`, which returns the driver for the
    model's interface (:class:`ModelExchangeStepper` or
    :class:`CoSimulationStepper`). Between steps, :meth:`set` changes tunable
    parameters and inputs and :meth:`get` reads any variables.

    Attributes
    ----------
    time : float
        The current simulation time (s).
    """

    def __init__(self, model: FMUModel, fmi: _FMI, *, start_time: float, parameters: dict[str, Any],
                 inputs: pd.DataFrame | None, max_step: float | None) -> None:
        self.model = model
        self.time = start_time
        self._finished = False
        self._fmi = fmi
        self._fmu = fmi.instance
        self._getters: dict[tuple[str, ...], Callable[[], npt.NDArray[np.float64]]] = {}
        self._setters: dict[tuple[str, ...], Callable[[Any], None]] = {}
        self._in_names: list[str] = []
        self._in_times: npt.NDArray[np.float64] | None = None
        self._in_table: npt.NDArray[np.float64] | None = None
        self._in_set: Callable[[Any], None] | None = None
        self._in_i, self._in_t0, self._in_t1 = 1, math.inf, -math.inf  # the interval _input_values used last
        self._last_set: dict[str, Any] = {}
        #: the maximum step given (None: the input table's smallest interval)
        self.max_step_given = max_step
        self._prepare_inputs(inputs)
        self._initialize(parameters, max_step)

    # -- what each driver provides ------------------------------------------------
    def _after_initialization(self) -> None:
        """Called inside initialisation, after ``exitInitializationMode``."""

    def _start(self, max_step: float | None) -> None:
        """Called once initialisation succeeded."""

    @abc.abstractmethod
    def _advance(self, t_next: float) -> None:
        """Advance from :attr:`time` to *t_next* (> :attr:`time`)."""

    @abc.abstractmethod
    def _apply_set(self, values: Mapping[str, Any], parameters_changed: bool, restart: bool = True) -> None:
        """Write *values* between steps (inside the error translation of :meth:`set`)."""

    # -- inputs -------------------------------------------------------------
    def _prepare_inputs(self, inputs: pd.DataFrame | None) -> None:
        if inputs is None:
            return
        where = "the inputs table"
        if "time" not in inputs.columns:
            raise DataError(f"{where} has no 'time' column (columns: {', '.join(map(str, inputs.columns))})")
        names = [str(c) for c in inputs.columns if c != "time"]
        model_inputs = self.model.info.inputs
        for name in names:
            if name not in model_inputs:
                raise FMUError(unknown_name("input", name, model_inputs, f"FMU {self.model.path.name}"))
            kind = self.model.variable(name).type
            if kind not in _REAL_TYPES:
                raise FMUError(f"input {name!r} of FMU {self.model.path.name} is {kind}; "
                               "only Real inputs can be driven from a table")
        try:
            t = inputs["time"].to_numpy(dtype=float)
            table = inputs[names].to_numpy(dtype=float) if names else np.zeros((len(t), 0))
        except (TypeError, ValueError) as exc:
            raise DataError(f"{where} has non-numeric values: {exc}") from None
        if t.size == 0:
            raise DataError(f"{where} has no rows")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise DataError(f"{where}: 'time' must be finite and strictly increasing")
        for j, name in enumerate(names):
            bad = ~np.isfinite(table[:, j])
            if bad.any():
                raise DataError(f"input {name!r} in {where} has {int(bad.sum())} NaN/inf values "
                                f"(first at t = {t[bad][0]:g} s)")
        if not names:
            return
        self._in_names = names
        self._in_times = t
        self._in_table = np.ascontiguousarray(table)
        self._in_set = self._setter(tuple(names))

    def extend_inputs(self, inputs: pd.DataFrame) -> None:
        """Go on with a longer table of the same inputs, whose first rows are the current table.

        For a run that receives its inputs as they come (the online mode). Only
        exact when the solver has not looked past the current table's end: a
        model-exchange stepper made with ``carry=True`` stops at every
        communication point, so it never has.
        """
        self.replace_inputs(inputs)

    def replace_inputs(self, inputs: pd.DataFrame) -> None:
        """Go on with another table of the same inputs (no restart).

        The run is the one the old table would have given when the new one holds
        the same rows over every time the solver still asks for: from the
        current time (its first row at or before it) to past the next stop,
        by more than one step of the solver (:mod:`trackingbox.stream`: a long
        run's input table, window by window). Inputs the run set explicitly
        stay off the table.
        """
        self._check_open()
        names = list(self._in_names)
        self._prepare_inputs(inputs)
        self._drop_inputs(set(self._in_names) - set(names))
        self._in_i, self._in_t0, self._in_t1 = 1, math.inf, -math.inf

    @property
    def input_times(self) -> npt.NDArray[np.float64] | None:
        """Sample times of the ``inputs`` table of this run (``None`` without one)."""
        return self._in_times

    def _input_values(self, t: float) -> npt.NDArray[np.float64]:
        times, table = self._in_times, self._in_table
        assert times is not None and table is not None
        if t <= times[0]:
            return table[0]
        if t >= times[-1]:
            return table[-1]
        # the solver asks for times close to the last one: try the last interval first (a
        # binary search per right-hand side evaluation was a third of a tracking run's cost)
        i = self._in_i
        t0, t1 = self._in_t0, self._in_t1
        if not t0 <= t < t1:
            i = int(np.searchsorted(times, t, side="right"))
            t0, t1 = times[i - 1], times[i]
            self._in_i, self._in_t0, self._in_t1 = i, t0, t1
        w = (t - t0) / (t1 - t0)
        return table[i - 1] + w * (table[i] - table[i - 1])

    def _apply_inputs(self, t: float) -> None:
        if self._in_set is not None:
            self._in_set(self._input_values(t))

    def _drop_inputs(self, names: set[str]) -> None:
        """Stop driving *names* from the table (the caller set them explicitly)."""
        if not self._in_names or not names.intersection(self._in_names):
            return
        keep = [j for j, n in enumerate(self._in_names) if n not in names]
        assert self._in_table is not None
        self._in_names = [self._in_names[j] for j in keep]
        self._in_table = np.ascontiguousarray(self._in_table[:, keep])
        self._in_set = self._setter(tuple(self._in_names)) if self._in_names else None

    # -- value access -----------------------------------------------------------
    def _getter(self, names: tuple[str, ...]) -> Callable[[], npt.NDArray[np.float64]]:
        getter = self._getters.get(names)
        if getter is not None:
            return getter
        fmu = self._fmu
        variables = [self.model.variable(n) for n in names]
        if all(v.type in ("Real", "Float64") for v in variables):
            getter = self._fmi.real_reader([v.valueReference for v in variables])
        else:
            calls = []
            for v in variables:
                kind = v.type
                if kind == "Enumeration":
                    kind = self._fmi.enumeration_type
                if kind in ("String", "Binary", "Clock"):
                    raise FMUError(f"variable {v.name!r} of FMU {self.model.path.name} is a {v.type}, not a number")
                calls.append((getattr(fmu, "get" + kind), v.valueReference))

            def getter() -> npt.NDArray[np.float64]:
                return np.array([float(g([vr])[0]) for g, vr in calls])
        self._getters[names] = getter
        return getter

    def _setter(self, names: tuple[str, ...]) -> Callable[[Any], None]:
        setter = self._setters.get(names)
        if setter is not None:
            return setter
        fmu = self._fmu
        variables = [self.model.variable(n) for n in names]
        if all(v.type in ("Real", "Float64") for v in variables):
            setter = self._fmi.real_writer([v.valueReference for v in variables])
        else:
            calls = []
            for v in variables:
                kind = v.type
                if kind == "Enumeration":
                    kind = self._fmi.enumeration_type
                py = {"Boolean": bool, "String": str}.get(kind, float if kind in _REAL_TYPES else int)
                calls.append((getattr(fmu, "set" + kind), v.valueReference, py))

            def setter(values: Any) -> None:
                for (s, vr, py), value in zip(calls, values):
                    s([vr], [py(value)])
        self._setters[names] = setter
        return setter

    # -- initialisation -----------------------------------------------------------
    def _settable_before_init(self, name: str) -> ModelVariable:
        v = self.model.variable(name)
        if v.causality in ("independent", "calculatedParameter") or v.variability == "constant":
            raise FMUError(f"variable {name!r} of FMU {self.model.path.name} is "
                           f"{v.causality if v.variability != 'constant' else 'a constant'}; it cannot be set")
        if v.causality == "output" or (v.causality == "local" and v.initial not in ("exact", "approx")):
            raise FMUError(f"variable {name!r} of FMU {self.model.path.name} is a computed "
                           f"{v.causality} variable; it cannot be set")
        return v

    def _initialize(self, parameters: dict[str, Any], max_step: float | None) -> None:
        model = self.model
        variables = {name: self._settable_before_init(name) for name in parameters}
        # inputs given as constants are not driven by the table any more
        self._drop_inputs(set(parameters))
        early = model.begin_run(parameters)
        early.update({n: parameters[n] for n, v in variables.items() if v.initial in ("exact", "approx")
                      or v.causality == "input"})
        late = {n: parameters[n] for n, v in variables.items() if n not in early}
        model.log_messages.clear()
        with _fmu_calls(f"initialisation of {model.path.name} at t = {self.time:g} s failed", model.log_messages):
            self._set_values(early)
            self._fmi.enter_initialization_mode(tolerance=model.tolerance, start_time=self.time)
            self._set_values(late)
            self._apply_inputs(self.time)
            self._fmu.exitInitializationMode()
            self._after_initialization()
        self._start(max_step)

    def _set_values(self, values: Mapping[str, Any]) -> None:
        if not values:
            return
        names = tuple(values)
        vals = [values[n] for n in names]
        for n, value in zip(names, vals):
            if isinstance(value, str):
                raise FMUError(f"value of {n!r} must be a number, not {value!r}")
        self._setter(names)(vals)

    def _check_open(self) -> None:
        if self._finished or self.model.closed:
            raise FMUError(f"this stepper of {self.model.path.name} is finished "
                           "(the model was closed or a newer run was started)")

    # -- public API -----------------------------------------------------------------
    def finish(self) -> None:
        """Make this stepper unusable (its model starts a newer run or closes).

        Its input table goes at once: the solver's callbacks make reference
        cycles that keep a finished stepper until the cyclic garbage collector
        runs, and a run restarted every checkpoint would otherwise hold one
        copy of a whole week's table per restart.
        """
        self._finished = True
        self._in_table = self._in_times = None
        self._in_set = None

    def step(self, t_next: float) -> None:
        """Integrate from :attr:`time` to *t_next*.

        Raises
        ------
        SimulationError
            The solver failed or the states became non-finite; names the time.
        """
        self._check_open()
        t_next = float(t_next)
        tol = 1e-12 * max(1.0, abs(t_next))
        if t_next < self.time - tol:
            raise SimulationError(f"cannot step {self.model.path.name} back in time from "
                                  f"t = {self.time:g} s to t = {t_next:g} s")
        if t_next <= self.time + tol:
            return
        self._advance(t_next)

    def set(self, values: Mapping[str, float], *, restart: bool = True) -> None:
        """Set tunable parameters and/or inputs before the next step.

        An input set here is no longer driven by the ``inputs`` table of this run.
        For model exchange, the change is a discontinuity: tunable parameters are
        set in event mode and the solver is re-initialised. With
        ``restart=False`` on a stepper made with ``carry=True``
        (:meth:`FMUModel.stepper`), the integrator is not re-initialised
        when it stands exactly at :attr:`time` and the event left the
        continuous states unchanged: CVODE goes on with its step size, order
        and history, and its error test absorbs the jump in the derivatives
        (for a small change; the caller decides what is small).
        :attr:`ModelExchangeStepper.restarts` and
        :attr:`ModelExchangeStepper.carried` count both outcomes.

        Raises
        ------
        FMUError
            Unknown names, or variables that cannot change during a run.
        """
        self._check_open()
        # values equal to what this method set last time change nothing: no event, no solver restart
        values = {n: v for n, v in values.items() if self._last_set.get(n) != v}
        if not values:
            return
        params = False
        for name in values:
            v = self.model.variable(name)
            if v.causality == "input":
                continue
            if v.causality == "parameter" and v.variability == "tunable":
                params = True
                continue
            raise FMUError(f"variable {name!r} of FMU {self.model.path.name} is "
                           f"{v.variability} {v.causality}; only tunable parameters and inputs can be set "
                           "between steps")
        self._drop_inputs(set(values))
        with _fmu_calls(f"setting {', '.join(values)} in {self.model.path.name} at t = {self.time:g} s failed",
                        self.model.log_messages):
            self._apply_set(values, params, restart)
        self.model.note_changed(n for n in values if self.model.variable(n).causality == "parameter")
        self._last_set.update(values)

    def get(self, names: Sequence[str]) -> npt.NDArray[np.float64]:
        """Current values of *names* as a float array (same order)."""
        self._check_open()
        return self._getter(tuple(names))()

    def reader(self, names: Sequence[str]) -> Callable[[], npt.NDArray[np.float64]]:
        """A function returning the current values of *names* (as :meth:`get`, without its checks).

        For tight loops; valid while this stepper is.
        """
        return self._getter(tuple(names))

    @abc.abstractmethod
    def get_continuous_states(self) -> npt.NDArray[np.float64]:
        """The continuous state vector (model exchange only), for checkpoints."""

    @abc.abstractmethod
    def set_continuous_states(self, x: npt.ArrayLike) -> None:
        """Overwrite the continuous state vector (model exchange only); the solver restarts."""

    @property
    def state_names(self) -> list[str]:
        """Names of the continuous states, in state-vector order (model exchange)."""
        md = self._fmi.model_description
        return [d.variable.derivative.name for d in md.derivatives if d.variable.derivative is not None]


class CoSimulationStepper(Stepper):
    """The co-simulation driver: the FMU integrates itself, one ``doStep`` per communication step.

    Inputs are applied at the start of each step and held over it.
    """

    def _advance(self, t_next: float) -> None:
        with _fmu_calls(f"simulation of {self.model.path.name} failed in the step from "
                        f"t = {self.time:g} s to t = {t_next:g} s", self.model.log_messages):
            self._apply_inputs(self.time)
            result = self._fmu.doStep(currentCommunicationPoint=self.time,
                                      communicationStepSize=t_next - self.time)
        if self._fmi.terminated(result):
            raise SimulationError(f"{self.model.path.name} requested termination at t = {t_next:g} s")
        self.time = t_next
        self._apply_inputs(self.time)

    def _apply_set(self, values: Mapping[str, Any], parameters_changed: bool, restart: bool = True) -> None:
        self._set_values(values)

    def get_continuous_states(self) -> npt.NDArray[np.float64]:
        """Not available: a co-simulation FMU keeps its states to itself (:class:`FMUError`)."""
        self._check_open()
        raise FMUError(f"{self.model.path.name} runs as co-simulation; its states are not accessible")

    def set_continuous_states(self, x: npt.ArrayLike) -> None:
        """Not available: a co-simulation FMU keeps its states to itself (:class:`FMUError`)."""
        self._check_open()
        raise FMUError(f"{self.model.path.name} runs as co-simulation; its states are not accessible")


#: CVODE's return flags (cvode.h): reached the stop time; found a root
_CV_TSTOP_RETURN = 1
_CV_ROOT_RETURN = 2


def _cvode_functions() -> tuple[Any, Any]:
    """``CVodeSetStopTime`` and ``CVodeGetCurrentTime`` from the CVODE library FMPy loads.

    FMPy binds only part of CVODE's API; these two are in the same library
    (SUNDIALS 7, documented in CVODE's user guide, "Optional inputs" and
    "Optional outputs").
    """
    from fmpy.sundials.cvode import sundials_cvode
    from fmpy.sundials.sundials_types import sunrealtype

    set_stop = getattr(sundials_cvode, "CVodeSetStopTime")
    set_stop.argtypes = [ctypes.c_void_p, sunrealtype]
    set_stop.restype = ctypes.c_int
    current = getattr(sundials_cvode, "CVodeGetCurrentTime")
    current.argtypes = [ctypes.c_void_p, ctypes.POINTER(sunrealtype)]
    current.restype = ctypes.c_int
    return set_stop, current


def _cvode_solver_class() -> type:
    """A CVodeSolver whose callbacks report Python errors to CVODE instead of swallowing them.

    Its :meth:`step` can also stop CVODE exactly at the target time (CVODE's
    stop time) instead of stepping past it and interpolating back, so the
    integrator's internal time is the communication point: a small change of
    a parameter or input there can then be carried by the integrator (no
    re-initialisation; see :meth:`ModelExchangeStepper.set`).
    """
    from fmpy.sundials import CVodeSolver
    from fmpy.sundials.cvode import CV_NORMAL, CVode, CVodeGetRootInfo
    from fmpy.sundials.sundials_types import sunrealtype

    set_stop, current = _cvode_functions()

    class _Solver(CVodeSolver):  # type: ignore[misc, valid-type]
        callback_error: BaseException | None = None
        #: stop exactly at each target time (see the class's docstring)
        exact = False

        def step(self, t, tNext):  # noqa: N803 - FMPy's signature
            """Integrate towards *tNext*; ``(root found, roots, time reached)`` as FMPy's ``step``."""
            if self.exact and set_stop(self.cvode_mem, tNext) != 0:
                raise RuntimeError(f"CVodeSetStopTime({tNext!r}) failed")
            if not self.discrete:
                self.get_x(self.px, self.nx)
            reached = sunrealtype(0.0)
            flag = CVode(self.cvode_mem, tNext, self.x, ctypes.byref(reached), CV_NORMAL)
            if not self.discrete:
                self.set_x(self.px, self.nx)
            roots = np.zeros(self.nz, dtype=np.int32)
            if flag < 0:
                raise RuntimeError("CVode error (code %s) in module %s, function %s: %s" % self.error_info)
            if flag == _CV_ROOT_RETURN:
                if CVodeGetRootInfo(self.cvode_mem, np.ctypeslib.as_ctypes(roots)) != 0:
                    raise RuntimeError("CVodeGetRootInfo failed")
            return flag == _CV_ROOT_RETURN, roots, reached.value

        def internal_time(self) -> float:
            """CVODE's own time: where its next step starts (after a stop-time return, the target)."""
            t = sunrealtype(0.0)
            if current(self.cvode_mem, ctypes.byref(t)) != 0:
                return math.nan
            return float(t.value)

        def f(self, t, y, ydot, user_data):  # noqa: D401 - CVODE right-hand side
            try:
                return super().f(t, y, ydot, user_data)
            except BaseException as exc:  # an FMU call failed: stop CVODE cleanly
                self.callback_error = exc
                return -1

        def g(self, t, y, gout, user_data):
            try:
                return super().g(t, y, gout, user_data)
            except BaseException as exc:
                self.callback_error = exc
                return -1

    return _Solver


class _NoInput:
    """Placeholder for FMPy's input object (inputs are applied in set_time)."""

    @staticmethod
    def apply(*args: Any, **kwargs: Any) -> None:
        return None


class ModelExchangeStepper(Stepper):
    """The model-exchange driver: CVODE (BDF) integrates the FMU's derivatives.

    Parameter changes, input overrides and state overwrites are discontinuities:
    the integrator is re-initialised after each, unless the stepper carries
    small changes (:meth:`carry`, ``set(..., restart=False)``). Time events
    and state events trigger FMI event iterations.

    Attributes
    ----------
    restarts, carried : int
        Changes made through :meth:`set` that re-initialised the integrator,
        and changes it carried.
    """

    def __init__(self, model: FMUModel, fmi: _FMI, *, start_time: float, parameters: dict[str, Any],
                 inputs: pd.DataFrame | None, max_step: float | None) -> None:
        md = fmi.model_description
        self._solver: Any = None
        self._next_event: float | None = None
        self._nx = int(md.numberOfContinuousStates or 0)
        self._nz = int(md.numberOfEventIndicators or 0)
        self._x = np.zeros(max(self._nx, 1))
        self._px = self._x.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        self._x_before = np.zeros_like(self._x)
        self.restarts = 0
        self.carried = 0
        super().__init__(model, fmi, start_time=start_time, parameters=parameters, inputs=inputs,
                         max_step=max_step)

    def _after_initialization(self) -> None:
        self._event_iteration(initial=True)

    def _start(self, max_step: float | None) -> None:
        fmu = self._fmu
        if max_step is None:
            max_step = float("inf")
            if self._in_times is not None and self._in_times.size > 1:
                max_step = float(np.min(np.diff(self._in_times)))
        solver_cls = _cvode_solver_class()
        n, get_x, set_x, get_dx, get_nominals = self._system()
        self._solver = solver_cls(
            nx=n, nz=self._nz,
            get_x=get_x, set_x=set_x,
            get_dx=get_dx,
            get_z=fmu.getEventIndicators,
            get_nominals=get_nominals,
            set_time=self._set_time, input=_NoInput(), startTime=self.time,
            maxStep=max_step, relativeTolerance=self.model.tolerance, maxNumSteps=100000,
        )
        self._check_states()

    def _system(self) -> tuple[int, Callable[..., Any], Callable[..., Any], Callable[..., Any], Callable[..., Any]]:
        """What CVODE integrates: its size and the get/set-state, derivative and nominal callbacks."""
        fmu = self._fmu
        return (self._nx, fmu.getContinuousStates, fmu.setContinuousStates, self._fmi.get_derivatives,
                fmu.getNominalsOfContinuousStates)

    def _set_time(self, t: float) -> None:
        self._fmu.setTime(t)
        if self._in_set is not None:
            self._in_set(self._input_values(t))

    def _event_iteration(self, initial: bool = False) -> None:
        fmu = self._fmu
        if not initial:
            fmu.enterEventMode()
        self._update_discrete_states()
        fmu.enterContinuousTimeMode()

    def _update_discrete_states(self) -> None:
        needed, terminate = True, False
        next_defined, next_time = False, 0.0
        while needed and not terminate:
            needed, terminate, next_defined, next_time = self._fmi.update_discrete_states()
        if terminate:
            raise SimulationError(f"{self.model.path.name} requested termination at t = {self.time:g} s")
        self._next_event = float(next_time) if next_defined else None

    def _check_states(self) -> None:
        if self._nx == 0:
            return
        self._fmu.getContinuousStates(self._px, self._nx)
        if not np.all(np.isfinite(self._x[: self._nx])):
            md = self._fmi.model_description
            bad = [d.variable.derivative.name for d, ok in zip(md.derivatives, np.isfinite(self._x))
                   if not ok and d.variable.derivative is not None]
            raise SimulationError(f"simulation of {self.model.path.name} produced non-finite states "
                                  f"{', '.join(map(repr, bad)) or ''} at t = {self.time:g} s")

    def _advance(self, t_next: float) -> None:
        fmu, solver = self._fmu, self._solver
        needs_completed = self._fmi.needs_completed_integrator_step()
        while self.time < t_next - 1e-12 * max(1.0, abs(t_next)):
            target = t_next
            if self._next_event is not None and self.time < self._next_event < t_next:
                target = self._next_event
            solver.callback_error = None
            try:
                state_event, _, t_ret = solver.step(self.time, target)
            except Exception as exc:
                cause: object = solver.callback_error or exc
                info = getattr(solver, "error_info", None)
                if solver.callback_error is None and info and len(info) > 3:
                    cause = str(info[3]).strip()
                raise _simulation_failure(f"solver failed in {self.model.path.name} between "
                                          f"t = {self.time:g} s and t = {target:g} s", cause,
                                          self.model.log_messages, solver=True) from None
            self.time = float(t_ret)
            with _fmu_calls(f"simulation of {self.model.path.name} failed at t = {self.time:g} s",
                            self.model.log_messages):
                self._set_time(self.time)
                step_event = False
                if needs_completed:
                    step_event, terminate = fmu.completedIntegratorStep()
                    if terminate:
                        raise SimulationError(f"{self.model.path.name} requested termination at "
                                              f"t = {self.time:g} s")
                time_event = self._next_event is not None and math.isclose(self.time, self._next_event)
                if state_event or step_event or time_event:
                    self._event_iteration()
                    solver.reset(self.time)
            self._check_states()
        self.time = t_next

    def carry(self) -> None:
        """From now on stop CVODE exactly at every communication point, so small changes can be carried."""
        self._solver.exact = True

    def _at_time(self) -> bool:
        """True if CVODE's internal time is :attr:`time` (it stopped there, or was re-initialised there)."""
        t_int = self._solver.internal_time()
        return abs(t_int - self.time) <= 1e-12 * max(1.0, abs(self.time))

    def _apply_set(self, values: Mapping[str, Any], parameters_changed: bool, restart: bool = True) -> None:
        carry = not restart and self._solver.exact and self._nx > 0 and self._at_time()
        if carry:
            self._fmu.getContinuousStates(self._px, self._nx)
            self._x_before[: self._nx] = self._x[: self._nx]
        if parameters_changed:
            self._fmu.enterEventMode()
            self._set_values(values)
            self._update_discrete_states()
            self._fmu.enterContinuousTimeMode()
        else:
            self._set_values(values)
        if carry:
            # the event must have left the states where CVODE has them, else it restarts
            self._fmu.getContinuousStates(self._px, self._nx)
            carry = bool(np.array_equal(self._x[: self._nx], self._x_before[: self._nx]))
        if carry:
            self.carried += 1
        else:
            self.restarts += 1
            self._solver.reset(self.time)

    def get_continuous_states(self) -> npt.NDArray[np.float64]:
        """The continuous state vector, for checkpoints."""
        self._check_open()
        self._fmu.getContinuousStates(self._px, self._nx)
        return self._x[: self._nx].copy()

    def set_continuous_states(self, x: npt.ArrayLike) -> None:
        """Overwrite the continuous state vector; the solver restarts."""
        self._check_open()
        arr = np.asarray(x, dtype=float).ravel()
        if arr.size != self._nx:
            raise FMUError(f"{self.model.path.name} has {self._nx} continuous states, not {arr.size}")
        self._x[: self._nx] = arr
        self._fmu.setContinuousStates(self._px, self._nx)
        self._solver.reset(self.time)


# ---------------------------------------------------------------------------
# forward sensitivities (model exchange, directional derivatives)
# ---------------------------------------------------------------------------

def directional_derivatives_reason(info: FMUInfo, interface: Interface = "ModelExchange") -> str | None:
    """Why the FMU's directional derivatives cannot give exact parameter sensitivities, or None if they can.

    Needs the model-exchange interface with ``providesDirectionalDerivatives``
    (FMI 3) / ``providesDirectionalDerivative`` (FMI 2), at least one continuous
    state, and no initial unknown the FMU computes from the parameters (a state
    or parameter solved by initial equations: its dependence on the parameters
    is not in the derivatives of the continuous-time equations, and the
    sensitivities would start wrong). Whether the FMU also accepts parameters
    as knowns is checked at run time (:meth:`SensitivityStepper.check_parameter_derivatives`).

    >>> info = FMUInfo(Path("cs.fmu"), "2.0", "M", ("CoSimulation",), ())
    >>> directional_derivatives_reason(info)
    'cs.fmu has no model-exchange interface'
    """
    md = info.model_description
    if interface != "ModelExchange" or "ModelExchange" not in info.interfaces:
        return f"{info.path.name} has no model-exchange interface"
    if md is None or md.modelExchange is None:
        return f"{info.path.name}: no model description read"
    me = md.modelExchange
    flag = ("providesDirectionalDerivatives" if info.fmi_version.startswith("3")
            else "providesDirectionalDerivative")
    if not (bool(getattr(me, "providesDirectionalDerivative", False)) or _declares(info.path, flag)):
        return f"{info.path.name} does not declare {flag}"
    if not md.derivatives:
        return f"{info.path.name} has no continuous states"
    states = {d.variable.derivative.name for d in md.derivatives if d.variable.derivative is not None}
    solved = [v.name for v in md.modelVariables
              if (v.causality == "calculatedParameter" and v.initial == "calculated")
              or (v.name in states and v.initial in ("approx", "calculated"))]
    if solved:
        return (f"{info.path.name} computes {', '.join(solved[:3])}{' ...' if len(solved) > 3 else ''} "
                "at initialisation (initial equations)")
    return None


def _declares(path: Path, flag: str) -> bool:
    """Whether the ``<ModelExchange>`` element of *path*'s model description sets *flag* to true.

    fmpy 0.3.32 reads FMI 3's ``providesDirectionalDerivatives`` under FMI 2's
    singular name and so never sees it; this reads the one attribute itself.
    """
    import xml.etree.ElementTree as ET

    try:
        with zipfile.ZipFile(path) as zf, zf.open("modelDescription.xml") as fh:
            for _, element in ET.iterparse(fh, events=("start",)):
                if element.tag == "ModelExchange":
                    return str(element.get(flag, "false")).strip().lower() in ("true", "1")
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
        return False
    return False


class SensitivityStepper(ModelExchangeStepper):
    """Model exchange with the forward sensitivities of the states w.r.t. tunable parameters.

    CVODE integrates the states and, with them, the sensitivity equations

    ``dS_j/dt = (df/dx) S_j + (df/dp_j) s_j``,  ``S_j = (dx/dp_j) s_j``,

    one block per parameter ``p_j`` scaled by ``s_j`` (so that ``S_j`` has the
    units and the nominal values of the states, and CVODE's error test treats
    it as it treats them). Each block's right-hand side is one directional
    derivative of the FMU: unknowns the state derivatives, knowns the states and
    ``p_j``, seed ``(S_j, s_j)``. The sensitivities start at zero (the states'
    start values do not depend on the parameters; see
    :func:`directional_derivatives_reason`). Outputs' sensitivities are
    ``(dy/dx) S_j / s_j + dy/dp_j`` (:meth:`output_sensitivities`), one more
    directional derivative per parameter.
    """

    #: Absolute tolerance of the sensitivity blocks relative to the states' (their nominals times
    #: the relative tolerance); 1 would control their error as tightly as the states'. Measured on
    #: the heat-exchanger bench twin (8 h run, rtol 1e-6, dx/dkht against a central difference at
    #: rtol 1e-10): factor 1 -> 3.7e-5 relative error at 4.0x the CPU of a plain run, 10 -> 4.8e-5
    #: at 2.6x, 100 -> 1.1e-4 at 1.7x, 1e4 -> 1.4e-4 at 1.7x (the steps are then the states'). The
    #: forward difference it replaces (step 1e-3 of the range) is off by 0.15 there.
    sensitivity_tolerance = 100.0

    def __init__(self, model: FMUModel, fmi: _FMI, *, start_time: float, parameters: dict[str, Any],
                 inputs: pd.DataFrame | None, max_step: float | None, wrt: Sequence[str],
                 scales: Sequence[float]) -> None:
        md = fmi.model_description
        nx = int(md.numberOfContinuousStates or 0)
        if nx == 0 or not md.derivatives:
            raise FMUError(f"{model.path.name} has no continuous states: no sensitivity equations to integrate")
        self._wrt = [str(n) for n in wrt]
        self._scales = np.asarray(scales, dtype=float)
        if self._scales.shape != (len(self._wrt),) or not np.all(np.isfinite(self._scales) & (self._scales > 0)):
            raise FMUError(f"sensitivity scales must be {len(self._wrt)} positive numbers, not {scales!r}")
        self._param_vr = []
        for name in self._wrt:
            v = model.variable(name, "parameter")
            if v.causality != "parameter" or v.variability != "tunable" or v.type not in _REAL_TYPES:
                raise FMUError(f"variable {name!r} of FMU {model.path.name} is {v.variability} {v.causality} "
                               f"({v.type}): sensitivities are taken w.r.t. tunable Real parameters only")
            self._param_vr.append(int(v.valueReference))
        self._state_vr = [int(d.variable.derivative.valueReference) for d in md.derivatives]
        self._der_vr = [int(d.variable.valueReference) for d in md.derivatives]
        self._S = np.zeros((len(self._wrt), nx))
        self._seed = np.zeros(nx + 1)
        self._out_calls: dict[tuple[str, ...], list[Callable[[Any], npt.NDArray[np.float64]]]] = {}
        self._jac_call: Callable[[Any], npt.NDArray[np.float64]] | None = None
        #: directional-derivative calls made so far (sensitivity equations and outputs)
        self.directional_calls = 0
        super().__init__(model, fmi, start_time=start_time, parameters=parameters, inputs=inputs,
                         max_step=max_step)

    @property
    def parameters(self) -> list[str]:
        """The parameters the sensitivities are taken with respect to."""
        return list(self._wrt)

    def _system(self) -> tuple[int, Callable[..., Any], Callable[..., Any], Callable[..., Any], Callable[..., Any]]:
        fmu, nx, m = self._fmu, self._nx, len(self._wrt)
        n = nx * (1 + m)
        S, seed, scales = self._S, self._seed, self._scales
        calls = [self._fmi.directional(self._der_vr, self._state_vr + [vr]) for vr in self._param_vr]
        get_derivatives = self._fmi.get_derivatives
        views: dict[int, npt.NDArray[np.float64]] = {}

        def view(ptr: Any) -> npt.NDArray[np.float64]:
            # CVODE passes the same few vectors again and again: one numpy view per address
            address = ctypes.addressof(ptr.contents)
            found = views.get(address)
            if found is None:
                found = views[address] = np.ctypeslib.as_array(ptr, (n,))
            return found

        def get_x(ptr: Any, size: int) -> None:
            fmu.getContinuousStates(ptr, nx)
            view(ptr)[nx:] = S.ravel()

        def set_x(ptr: Any, size: int) -> None:
            fmu.setContinuousStates(ptr, nx)
            S[:] = view(ptr)[nx:].reshape(m, nx)

        def get_dx(ptr: Any, size: int) -> None:
            get_derivatives(ptr, nx)
            out = view(ptr)
            for j, call in enumerate(calls):
                seed[:nx] = S[j]
                seed[nx] = scales[j]
                out[nx * (j + 1): nx * (j + 2)] = call(seed)
            self.directional_calls += m

        def get_nominals(ptr: Any, size: int) -> None:
            fmu.getNominalsOfContinuousStates(ptr, nx)
            out = np.ctypeslib.as_array(ptr, (n,))
            out[nx:] = np.tile(out[:nx], m) * self.sensitivity_tolerance

        return n, get_x, set_x, get_dx, get_nominals

    def _start(self, max_step: float | None) -> None:
        super()._start(max_step)
        self._jac_fn = _block_jacobian(self)  # kept referenced while CVODE may call it
        _set_jacobian(self._solver, self._jac_fn)

    def state_jacobian(self) -> npt.NDArray[np.float64]:
        """``d(der x)/dx`` at the current time and states: one directional derivative per state."""
        nx = self._nx
        call = self._jac_call
        if call is None:
            call = self._jac_call = self._fmi.directional(self._der_vr, self._state_vr)
        out = np.empty((nx, nx))
        seed = np.zeros(nx)
        for i in range(nx):
            seed[i] = 1.0
            out[:, i] = call(seed)
            seed[i] = 0.0
        self.directional_calls += nx
        return out

    def state_sensitivities(self) -> npt.NDArray[np.float64]:
        """``dx/dp`` now: shape (number of states, number of parameters)."""
        self._check_open()
        return (self._S / self._scales[:, None]).T.copy()

    def output_sensitivities(self, names: Sequence[str]) -> npt.NDArray[np.float64]:
        """``dy/dp`` of the variables *names* now: shape (len(names), number of parameters)."""
        self._check_open()
        key = tuple(names)
        calls = self._out_calls.get(key)
        if calls is None:
            vrs = [int(self.model.variable(n, "output variable").valueReference) for n in key]
            calls = [self._fmi.directional(vrs, self._state_vr + [vr]) for vr in self._param_vr]
            self._out_calls[key] = calls
        nx, seed = self._nx, self._seed
        out = np.empty((len(key), len(calls)))
        with _fmu_calls(f"directional derivatives of {self.model.path.name} failed at t = {self.time:g} s",
                        self.model.log_messages):
            for j, call in enumerate(calls):
                seed[:nx] = self._S[j]
                seed[nx] = self._scales[j]
                out[:, j] = call(seed) / self._scales[j]
        self.directional_calls += len(calls)
        return out

    def check_parameter_derivatives(self, relative_step: float = 1e-6) -> dict[str, float]:
        """How far the FMU's ``d(der x)/dp_j`` is from a central difference, per parameter, now.

        Each parameter is moved by ``relative_step`` times its scale either way
        (in event mode, as :meth:`set` does), the state derivatives read, and the
        parameter restored; the solver restarts. Returns, per parameter, the
        largest absolute mismatch divided by the largest magnitude of either
        vector (0 where both vanish). An FMU that ignores a parameter seed (it
        exports derivatives w.r.t. states and inputs only) shows 1 here.
        """
        self._check_open()
        nx = self._nx
        buf = np.zeros(nx)
        pbuf = buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        out: dict[str, float] = {}
        with _fmu_calls(f"checking the directional derivatives of {self.model.path.name} failed",
                        self.model.log_messages):
            for name, vr, scale in zip(self._wrt, self._param_vr, self._scales):
                seed = np.zeros(nx + 1)
                seed[nx] = 1.0
                exact = self._fmi.directional(self._der_vr, self._state_vr + [vr])(seed)
                value = float(self.get([name])[0])
                h = relative_step * scale
                rows = []
                for v in (value + h, value - h):
                    self._apply_set({name: v}, True)
                    self._fmi.get_derivatives(pbuf, nx)
                    rows.append(buf.copy())
                self._apply_set({name: value}, True)
                fd = (rows[0] - rows[1]) / (2 * h)
                size = max(float(np.max(np.abs(fd))), float(np.max(np.abs(exact))))
                out[name] = float(np.max(np.abs(exact - fd)) / size) if size > 0 else 0.0
        return out


def _block_jacobian(stepper: SensitivityStepper) -> Any:
    """CVODE's Jacobian callback for the augmented system: ``d(der x)/dx`` repeated on the diagonal.

    The exact Jacobian of the sensitivity blocks also has ``d((df/dx) S_j)/dx`` below
    the diagonal; leaving it out (as CVODES's simultaneous corrector does) changes
    only the Newton iteration's convergence rate, never the solution, which the
    corrector's own convergence and error tests govern. It costs ``nx``
    directional derivatives instead of ``nx * (1 + m)`` right-hand sides.
    """
    from fmpy.sundials.libraries import sundials_sunmatrixdense
    from fmpy.sundials.nvector_serial import NV_DATA_S
    from fmpy.sundials.sundials_matrix import SUNMatrix
    from fmpy.sundials.sundials_nvector import N_Vector

    data_of = sundials_sunmatrixdense.SUNDenseMatrix_Data
    data_of.argtypes = [SUNMatrix]
    data_of.restype = ctypes.POINTER(ctypes.c_double)
    prototype = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double, N_Vector, N_Vector, SUNMatrix, ctypes.c_void_p,
                                 N_Vector, N_Vector, N_Vector)
    nx, m = stepper._nx, len(stepper._wrt)
    n = nx * (1 + m)
    solver = stepper._solver

    def jac(t: float, y: Any, fy: Any, matrix: Any, user_data: Any, tmp1: Any, tmp2: Any, tmp3: Any) -> int:
        try:
            solver.set_time(t)
            solver.set_x(NV_DATA_S(y), n)
            block = stepper.state_jacobian()
            a = np.ctypeslib.as_array(data_of(matrix), (n, n))  # row k holds column k (column-major)
            a[:] = 0.0
            for b in range(m + 1):
                a[b * nx:(b + 1) * nx, b * nx:(b + 1) * nx] = block.T
            return 0
        except BaseException as exc:  # an FMU call failed: stop CVODE cleanly (reported as a solver failure)
            solver.callback_error = exc
            return -1

    return prototype(jac)


def _set_jacobian(solver: Any, jac: Any) -> None:
    from fmpy.sundials.libraries import sundials_cvode

    set_jac = sundials_cvode.CVodeSetJacFn
    set_jac.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
    set_jac.restype = ctypes.c_int
    flag = set_jac(solver.cvode_mem, ctypes.cast(jac, ctypes.c_void_p))
    if flag != 0:
        raise FMUError(f"CVodeSetJacFn failed (flag {flag})")
