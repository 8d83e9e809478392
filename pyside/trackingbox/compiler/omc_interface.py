"""Does an FMU expose the names a spec (or the embedded path) expects?

An FMU built by OpenModelica must offer the twin's parameters, inputs and
outputs under the names the embedded path gives them (the flattened Modelica
names, ``hx.kht``), with the same causality, or ``pair``, ``estimate`` and
``track`` cannot use it. :func:`compare_interface` lists every difference,
naming each variable; :meth:`InterfaceReport.raise_for_problems` turns them into
one :class:`~trackingbox.errors.CompileError`.
"""
from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from ..errors import CompileError, did_you_mean

__all__ = ["ExpectedInterface", "InterfaceProblem", "InterfaceReport", "compare_interface"]

Problem = Literal["missing", "causality", "not_tunable", "type"]


@dataclass(frozen=True)
class ExpectedInterface:
    """The names an FMU must expose.

    Attributes
    ----------
    parameters:
        Real parameters the toolchain sets (``hx.kht``).
    inputs:
        Inputs the toolchain drives.
    outputs:
        Outputs the toolchain reads.
    """

    parameters: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()

    @classmethod
    def from_spec(cls, spec: Any) -> ExpectedInterface:
        """The twin names of a loaded :class:`trackingbox.spec.Spec`: its ``[[parameters]]``,
        the FMU inputs of ``[inputs]`` and the FMU outputs of ``[outputs]``."""
        return cls(tuple(p.name for p in spec.parameters), tuple(dict.fromkeys(spec.inputs.values())),
                   tuple(dict.fromkeys(spec.outputs.values())))

    @classmethod
    def from_fmu(cls, fmu: Path | Any) -> ExpectedInterface:
        """Every Real parameter, input and output of an FMU (e.g. the embedded path's build of
        the same model), to check another build against it."""
        info = _info(fmu)
        return cls(tuple(v.name for v in info.variables if v.causality == "parameter" and _real(v.type)),
                   tuple(info.inputs), tuple(info.outputs))


@dataclass(frozen=True)
class InterfaceProblem:
    """One difference: *name* expected as *expected*, found as *found* (``""`` when missing)."""

    name: str
    expected: str
    problem: Problem
    found: str = ""
    hint: str = ""

    def __str__(self) -> str:
        if self.problem == "missing":
            return f"{self.expected} {self.name!r} is not in the FMU{self.hint}"
        if self.problem == "causality":
            article = "an" if self.found[:1] in "aeiou" else "a"
            return f"{self.expected} {self.name!r} is {article} {self.found} variable in the FMU"
        if self.problem == "type":
            return f"{self.expected} {self.name!r} is of type {self.found}, not Real"
        return (f"parameter {self.name!r} is {self.found} in the FMU, not tunable: it can be set before "
                f"initialisation only (pair and track change parameters between steps)")


@dataclass(frozen=True)
class InterfaceReport:
    """The result of :func:`compare_interface`."""

    fmu: Path
    problems: tuple[InterfaceProblem, ...] = field(default_factory=tuple)

    @property
    def ok(self) -> bool:
        return not self.problems

    def raise_for_problems(self, what: str = "") -> None:
        """Raise one :class:`CompileError` listing every problem (nothing when there is none)."""
        if self.problems:
            lines = "".join(f"\n  {p}" for p in self.problems)
            raise CompileError(f"{what or self.fmu.name} does not expose the expected variables "
                               f"({len(self.problems)} difference{'s' if len(self.problems) > 1 else ''}):{lines}")

    def to_json(self) -> dict:
        return {"fmu": str(self.fmu), "ok": self.ok,
                "problems": [{"name": p.name, "expected": p.expected, "problem": p.problem, "found": p.found}
                             for p in self.problems]}


def _info(fmu: Path | Any) -> Any:
    from ..fmu import read_info

    return read_info(fmu) if isinstance(fmu, (str, Path)) else fmu


def _real(type_: str) -> bool:
    return type_ in ("Real", "Float64", "Float32")


def _key(name: str) -> str:
    return re.sub(r"[^0-9a-z]", "", name.lower())


def _last(name: str) -> str:
    return re.split(r"[._]", name)[-1]


def _suggest(name: str, candidates: list[str]) -> str:
    """Near names: the same name spelt with other separators (``hx.kht`` / ``hx_kht``), one that
    ends with it (``hx_UA`` for ``UA``), else :func:`did_you_mean`'s close matches."""
    key = _key(name)
    same = [c for c in candidates if _key(c) == key or _last(c) == name or _last(name) == c]
    if same:
        return " (did you mean " + ", ".join(repr(c) for c in same[:3]) + "?)"
    return did_you_mean(name, candidates)


def compare_interface(fmu: Path | Any, expected: ExpectedInterface, *, require_tunable: bool = True
                      ) -> InterfaceReport:
    """Compare an FMU's model description with the expected names.

    Parameters
    ----------
    fmu:
        Path of the FMU, or its :class:`trackingbox.fmu.FMUInfo`.
    expected:
        The parameters, inputs and outputs that must be there.
    require_tunable:
        Report parameters whose variability is not ``tunable`` (FMI ``fixed``
        parameters can be set before initialisation only).

    Returns
    -------
    InterfaceReport
        Every difference, in the order parameters, inputs, outputs.
    """
    info = _info(fmu)
    by_name = {v.name: v for v in info.variables}
    problems: list[InterfaceProblem] = []

    def check(names: Iterable[str], role: str, causalities: tuple[str, ...]) -> None:
        candidates = [v.name for v in info.variables if v.causality in causalities]
        for name in names:
            v = by_name.get(name)
            if v is None:
                problems.append(InterfaceProblem(name, role, "missing", hint=_suggest(name, candidates)))
            elif v.causality not in causalities:
                problems.append(InterfaceProblem(name, role, "causality", v.causality))
            elif not _real(v.type):
                problems.append(InterfaceProblem(name, role, "type", v.type))
            elif role == "parameter" and require_tunable and v.variability != "tunable":
                problems.append(InterfaceProblem(name, role, "not_tunable", v.variability))

    check(expected.parameters, "parameter", ("parameter",))
    check(expected.inputs, "input", ("input",))
    check(expected.outputs, "output", ("output",))
    return InterfaceReport(Path(info.path), tuple(problems))
