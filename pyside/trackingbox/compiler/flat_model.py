"""The flat translation's data: one scalar variable, an assert, the initialisation problem and the
explicit model (:mod:`.flatten` builds them, :mod:`.fmi_export` writes them into an FMU).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca

from .events import EventSystem


REAL, INTEGER, BOOLEAN, STRING = 0, 1, 2, 3

Value = Any  # float | bool | ca.MX | np.ndarray (object array of the former)


@dataclass
class ScalarVar:
    """One scalar of a flattened variable."""

    name: str
    kind: str  # "parameter" | "structural" | "constant" | "input" | "continuous"
    type: int
    top_level: bool
    output: bool
    start_node: Any
    binding_node: Any
    index: tuple[int, ...]
    attrs: dict[str, Any]
    description: str | None
    fixed: bool | None = None
    sym: ca.MX | None = None
    value: Any = None  # evaluated value for structural/constant
    evaluate: bool = False  # a Real parameter with annotation(Evaluate = true) (its own or a final binding's)


def string_attr(node) -> str | None:
    """A variable attribute's value where it is a string literal (``unit``, ``displayUnit``), else None."""
    if isinstance(node, str):
        return node
    if isinstance(node, dict):
        lit = node.get("Literal")
        if lit and isinstance(lit.get("value"), dict) and "String" in lit["value"]:
            return str(lit["value"]["String"])
    return None


@dataclass(frozen=True)
class Assertion:
    """One ``assert(condition, message, level)`` of the model or of an inlined function."""

    condition: ca.MX  # 1 where the assert holds, 0 where it fails
    message: str
    level: str  # "error" | "warning"
    origin: str


def merged_asserts(asserts: list[Assertion]) -> list[Assertion]:
    """One assert per message and level, in the order of their first appearance, holding where all of
    them hold; a failure still names its message. Traced functions repeat their asserts at each call
    (IF97's ``rho_ph`` recorded ``g1``'s four asserts 1 312 times each, 6 353 outputs for 28 messages;
    ``MomentumBalanceFittings`` has 1 524 asserts, one output each of the model function)."""
    groups: dict[tuple[str, str], list[Assertion]] = {}
    for a in asserts:
        groups.setdefault((a.message, a.level), []).append(a)
    out = []
    for group in groups.values():
        first = group[0]
        cond = first.condition if len(group) == 1 else ca.mmin(ca.vertcat(*[a.condition for a in group]))
        out.append(Assertion(condition=cond, message=first.message, level=first.level, origin=first.origin))
    return out


@dataclass(frozen=True)
class InitialSystem:
    """The initialisation problem solved when the FMU leaves initialisation mode.

    ``residual`` (one entry per equation) is expressed in ``unknowns`` (free
    states, then ``fixed = false`` parameters) and ``knowns`` (time,
    parameters, inputs, fixed states); no algebraic variable or derivative
    is left in it.
    """

    unknowns: list[ca.MX]
    knowns: list[ca.MX]
    residual: list[ca.MX]
    free_states: list[str]
    computed_parameters: list[str]
    origins: list[str]
    guesses: list[ca.MX] = field(default_factory=list)
    solution: list[ca.MX] = field(default_factory=list)
    """The unknowns solved block by block (a scalar equation linear in its unknown explicitly, a loop by
    Newton from ``guesses``, the unknowns' values when the FMU leaves initialisation mode), as
    expressions in ``guesses`` and ``knowns``; empty: one Newton solve of all ``residual``."""


@dataclass(frozen=True)
class LoopMemory:
    """One tearing variable of one of the model's algebraic loops and the FMU variable ``sym``
    (``_tbx_m<j>``) that keeps its last converged value, Newton's guess at the next evaluation
    (``start``, its start value, until the loop has solved: .loop_solve.warm_solution)."""

    sym: ca.MX
    start: float
    tear: str
    loop: str
    indicator: str = ""
    """The FMU variable of the loop's event indicator (.loop_solve.branch_solution): the runtime keeps
    the solution only where it is not negative."""


@dataclass
class ExplicitModel:
    """The causalised model, ready for FMU export.

    ``assignments`` are in evaluation order; each assigns an unknown symbol (an
    algebraic variable, a calculated parameter, or a state derivative
    placeholder) an expression in states, inputs, parameters, time and earlier
    unknowns.
    """

    name: str
    time: ca.MX
    parameters: list[ScalarVar]
    calculated: list[ScalarVar]
    inputs: list[ScalarVar]
    states: list[ScalarVar]
    algebraics: list[ScalarVar]
    derivative: dict[str, ca.MX]  # state name -> placeholder symbol of der(state)
    assignments: list[tuple[ca.MX, ca.MX]]
    n_loops: int = 0
    loop_sizes: list[int] = field(default_factory=list)
    unused_parameters: list[str] = field(default_factory=list)
    torn_sizes: list[tuple[int, int]] = field(default_factory=list)
    asserts: list[Assertion] = field(default_factory=list)
    initial: InitialSystem | None = None
    events: EventSystem | None = None
    discrete: list[ScalarVar] = field(default_factory=list)
    loop_memory: list[LoopMemory] = field(default_factory=list)


def kind_of(node: Any) -> tuple[str, Any]:
    if isinstance(node, dict) and len(node) == 1:
        key = next(iter(node))
        return key, node[key]
    return type(node).__name__, node
