"""``der(v)`` in an initial equation where ``v`` is no state.

The derivative of a variable is its time derivative as the model defines it (MLS 3.7.4), whether or not
the variable is a state. Modelica.Fluid's vessels initialise a steady state with ``der(medium.T) = 0``
(or ``der(medium.h) = 0``) while the embedded path keeps the balances' own variables, mass and internal
energy, as states (MSL ``Fluid.Examples.HeatingSystem``'s tank): there ``medium.T`` is an algebraic
variable, a function of the states (and perhaps of time), which the causalised model gives as an explicit
expression or as the solution of an algebraic loop. Its derivative follows by the chain rule,

    der(v) = dv/dx * der(x) + dv/dt,

a forward derivative (``jtimes``) of v's expression in the states x and time, along the states'
derivatives (the model's own equations give them, :meth:`.flat_systems.SystemAssembly._initial_system`
substitutes them) and 1 for time. Through an algebraic loop, the derivative is that of its rootfinder
(the implicit function theorem). Discrete variables, held relations and parameters are constant between
events: their derivatives are 0. A variable that depends on an input is refused (its derivative would need
the input's, which the FMU is not given), naming the equation.

Where index reduction (:mod:`.index`) made the variable a state after all, its derivative is the state's;
where it made a dummy derivative ``der(v)`` an algebraic variable, that variable.
"""
from __future__ import annotations

from typing import Any

import casadi as ca

from .flat_model import ScalarVar
from .flat_systems import substituted


class InitialDerivativeError(Exception):
    """``der(name)`` cannot be expressed through the states: *why* says what it depends on."""

    def __init__(self, name: str, why: str):
        super().__init__(f"der({name}): {why}")
        self.name = name
        self.why = why


def derivative_values(pending: list[str], scalars: dict[str, ScalarVar], states: list[ScalarVar],
                      derivative: dict[str, ca.MX], assignments: list[tuple[ca.MX, ca.MX]],
                      time: ca.MX) -> dict[str, ca.MX]:
    """{name: the value of der(name)} for each of *pending* (variables whose derivative an initial
    equation takes, none of them a state when the equations were read), in the states, their derivative
    symbols (*derivative*, by state name), time and constants; raises :class:`InitialDerivativeError`."""
    out: dict[str, ca.MX] = {}
    todo: list[str] = []
    for name in pending:
        dummy = scalars.get(f"der({name})")
        if name in derivative:  # a state chosen by index reduction
            out[name] = derivative[name]
        elif dummy is not None and dummy.kind == "continuous" and dummy.sym is not None:
            out[name] = dummy.sym
        else:
            todo.append(name)
    if not todo:
        return out
    values = substituted([scalars[n].sym for n in todo], assignments)
    state_names = {s.name for s in states}
    inputs = {n for n, sv in scalars.items() if sv.kind == "input"}
    for name, value in zip(todo, values):
        used = {s.name() for s in ca.symvar(value)}
        if used & inputs:
            raise InitialDerivativeError(name, f"{name} depends on the input {sorted(used & inputs)[0]}, whose "
                                         "derivative the FMU is not given")
        unsolved = sorted(n for n in used if n not in state_names and n in scalars and scalars[n].kind == "continuous")
        if unsolved:
            raise InitialDerivativeError(name, f"{name} is not given by the model's equations as a function "
                                         f"of the states (it depends on {', '.join(unsolved[:4])})")
        seeds = [s.sym for s in states] + [time]
        tangent = [derivative[s.name] for s in states] + [ca.MX(1.0)]
        out[name] = ca.jtimes(value, ca.vertcat(*seeds), ca.vertcat(*tangent))
    return out


def with_initial_derivatives(tr: Any, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar],
                             assignments: list[tuple[ca.MX, ca.MX]]) -> list[tuple[ca.MX, str]]:
    """The initial *residuals* of translator *tr* with each ``der(v)`` of a variable that was no state
    (``tr._initial_ders``: name -> (its symbol, the span of the first equation using it)) replaced by its
    value (:func:`derivative_values`); one that has none is refused naming the equation."""
    pending: dict[str, tuple[ca.MX, Any]] = getattr(tr, "_initial_ders", {}) or {}
    if not pending:
        return residuals
    try:
        values = derivative_values(list(pending), tr.scalars, states, tr.der_placeholders, assignments, tr.time)
    except InitialDerivativeError as exc:
        raise tr.unsupported(f"der({exc.name}) in an initial equation, where {exc.name} is not a state and "
                             f"{exc.why}", r"\bder\s*\(", span=pending[exc.name][1]) from None
    syms = [pending[n][0] for n in values]
    exprs = ca.substitute([r for r, _ in residuals], syms, [values[n] for n in values])
    return [(e, origin) for e, (_, origin) in zip(exprs, residuals)]
