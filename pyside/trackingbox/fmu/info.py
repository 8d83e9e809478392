"""An FMU's interface as small frozen records: :func:`read_info`, :class:`FMUInfo`, :class:`Variable`.

fmpy's :class:`~fmpy.model_description.ModelDescription` is kept (``FMUInfo.model_description``),
not re-parsed; errors name the file and the problem (:class:`~trackingbox.errors.FMUError`).
"""
from __future__ import annotations

import logging
import os
import struct
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from fmpy.model_description import (
    ModelDescription,
    ModelVariable,
    ValidationError,
    read_model_description,
)

from .. import config
from ..errors import FMUError, unknown_name

log = logging.getLogger(__name__)

Interface = Literal["ModelExchange", "CoSimulation"]

REAL_TYPES = frozenset({"Real", "Float64", "Float32"})
NUMERIC_TYPES = REAL_TYPES | frozenset(
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


#: What to do with a ``fixed`` parameter of a co-simulation-only FMU (one line, see :func:`change_refusal`).
FIXED_PARAMETER_REMEDY = (
    "export the FMU with model exchange as well (OpenModelica: buildModelFMU(..., fmuType=\"me_cs\"); "
    "Dymola: translateModelFMU(..., fmiType=\"all\")), which trackingbox re-initialises at each change, "
    "or compile the model's Modelica source here with `trackingbox compile SOURCE --model NAME "
    "--backend embedded` (every parameter tunable); see docs/your-own-model.md"
)


def change_refusal(info: FMUInfo, name: str, interface: str | None = None) -> str | None:
    """Why *name* cannot change between two steps of a run of this FMU, or None if it can.

    Inputs and ``tunable`` parameters change between steps as FMI allows. A
    ``fixed`` parameter can change only before initialisation: on the
    model-exchange interface a run changes it by re-initialising the FMU at the
    current time and restoring its continuous states
    (:meth:`~trackingbox.fmu.steppers.ModelExchangeStepper.set`); a run on the
    co-simulation interface cannot restore its states, so the answer names what
    to do instead. *interface* is the one the run uses (default: model exchange
    where the FMU offers it, as :class:`~trackingbox.fmu.FMUModel` chooses).

    >>> v = Variable("k", "parameter", "fixed", "Real", 1.0, None, None, None, None, "", 1)
    >>> change_refusal(FMUInfo(Path("me.fmu"), "2.0", "M", ("ModelExchange",), (v,)), "k") is None
    True
    >>> change_refusal(FMUInfo(Path("cs.fmu"), "2.0", "M", ("CoSimulation",), (v,)), "k").startswith(
    ...     "parameter 'k' of FMU cs.fmu is 'fixed' (FMI: set only before")
    True
    """
    v = info.variable(name)
    if v.causality == "input" or (v.causality == "parameter" and v.variability == "tunable"):
        return None
    if v.causality == "parameter" and v.variability == "fixed":
        if interface is None:
            interface = "ModelExchange" if "ModelExchange" in info.interfaces else "CoSimulation"
        if interface == "ModelExchange":
            return None
        return (f"parameter {name!r} of FMU {info.path.name} is 'fixed' (FMI: set only before initialisation) "
                f"and the FMU runs as co-simulation, whose states cannot be restored after a re-initialisation, "
                f"so it cannot follow a tracking controller: {FIXED_PARAMETER_REMEDY}")
    return (f"variable {name!r} of FMU {info.path.name} is {v.variability} {v.causality}; only tunable parameters "
            f"and inputs can be set between steps (fixed parameters too, on model exchange)")


def float_or_none(text: Any) -> float | None:
    if text is None:
        return None
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def start_value(v: ModelVariable) -> float | bool | str | None:
    if v.start is None:
        return None
    if v.type == "Boolean":
        return str(v.start).strip().lower() in {"true", "1"}
    if v.type in NUMERIC_TYPES:
        value = float_or_none(v.start)
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
        start=start_value(v),
        min=float_or_none(_attr(v, "min")),
        max=float_or_none(_attr(v, "max")),
        nominal=float_or_none(_attr(v, "nominal")),
        unit=_attr(v, "unit"),
        description=v.description,
        value_reference=int(v.valueReference) if v.valueReference is not None else -1,
    )


#: most entries an FMU archive may have
MAX_ENTRIES = 20_000
#: most bytes an FMU may inflate to (``TRACKINGBOX_FMU_MAX_BYTES`` overrides)
MAX_EXTRACTED_BYTES = config.setting("fmu_max_bytes").default
#: largest modelDescription.xml read (bytes)
MAX_DESCRIPTION_BYTES = 200 << 20


def zip_entry_count(path: Path) -> int | None:
    """The number of entries a ZIP archive's end record declares (ZIP64 too), or None if it cannot be read."""
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


def _read_model_description(path: Path) -> ModelDescription:
    """Read (and, where possible, validate) the model description of *path*."""
    if not path.exists():
        raise FMUError(f"FMU {path} does not exist")
    if path.is_dir():
        raise FMUError(f"FMU {path} is a directory, not an .fmu file")
    if not zipfile.is_zipfile(path):
        raise FMUError(f"FMU {path} is not a valid FMU: it is not a ZIP archive")
    entries = zip_entry_count(path)
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
        start_time=float_or_none(exp.startTime) if exp else None,
        stop_time=float_or_none(exp.stopTime) if exp else None,
        tolerance=float_or_none(exp.tolerance) if exp else None,
        step_size=float_or_none(exp.stepSize) if exp else None,
        number_of_states=int(md.numberOfContinuousStates or 0),
        model_description=md,
    )



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
        lo = float_or_none(v.min)
        hi = float_or_none(v.max)
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            problems.append(f"{name} = {value:g} is outside [{'-inf' if lo is None else f'{lo:g}'}, "
                            f"{'inf' if hi is None else f'{hi:g}'}] that {info.path.name} declares")
    if problems:
        raise FMUError(f"{where}: " + "; ".join(problems))
