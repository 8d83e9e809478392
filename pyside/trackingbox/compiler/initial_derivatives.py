"""``der(v)`` in an initial equation where ``v`` is no state.

The derivative of a variable is its time derivative as the model defines it (MLS 3.7.4), whether or not
the variable is a state. Modelica.Fluid's vessels initialise a steady state with ``der(medium.T) = 0``
(or ``der(medium.h) = 0``) while the embedded path keeps the balances' own variables, mass and internal
energy, as states (MSL ``Fluid.Examples.HeatingSystem``'s pipes): there ``medium.T`` is an algebraic
variable, which the model's sorted blocks (:mod:`.causalize`) give from the states (and perhaps time).
Its derivative follows by differentiating those blocks, in the model's order: a block r(z, y) = 0 in its
unknowns z, with y the states, time and earlier blocks' unknowns, gives

    dz/dt = -(dr/dz)^-1 (dr/dy dy/dt),

dy/dt the states' derivative symbols (the model's equations give them), 1 for time, and the earlier
blocks' results; for an explicit equation this is the chain rule, for an algebraic loop the implicit
function theorem. The result is in the model's own symbols (states, their derivatives, algebraic
variables): the initialisation problem substitutes their causalised values
(:meth:`.flat_systems.SystemAssembly._initial_system`), or solves it together with the model's
equations, from the variables' start values (``_whole_initial_solution``), never evaluating a loop's
solution at states that are only a guess. Parameters and discrete variables are constant between
events. A variable that depends on an input, or on a state's derivative, is refused naming the
equation (its derivative would need the input's, which the FMU is not given, or a second derivative).

Where index reduction (:mod:`.index`) made the variable a state after all, its derivative is the state's;
where it made a dummy derivative ``der(v)`` an algebraic variable, that variable.
"""
from __future__ import annotations

from typing import Any

import casadi as ca

from .flat_model import ScalarVar


class InitialDerivativeError(Exception):
    """``der(name)`` cannot be expressed through the states: *why* says what it depends on."""

    def __init__(self, name: str, why: str):
        super().__init__(f"der({name}): {why}")
        self.name = name
        self.why = why


def derivative_values(pending: list[str], scalars: dict[str, ScalarVar], states: list[ScalarVar],
                      derivative: dict[str, ca.MX], system: tuple[Any, list[tuple[ca.MX, str]], list[ca.MX]],
                      time: ca.MX) -> dict[str, ca.MX]:
    """{name: the value of der(name)} for each of *pending* (variables whose derivative an initial
    equation takes, none of them a state when the equations were read), in the model's own symbols:
    the states, their derivative symbols (*derivative*, by state name), the algebraic variables, time and
    constants. *system*: the model's sorted blocks, equations and unknowns (:mod:`.causalize`). Raises
    :class:`InitialDerivativeError`."""
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
    tangent: dict[str, ca.MX] = {s.name: derivative[s.name] for s in states}
    tangent[time.name()] = ca.MX(1.0)
    for name in todo:  # (a parameter or discrete variable: 0 between events)
        out[name] = _tangent(name, tangent, scalars, derivative, system)
    return out


def _tangent(name: str, tangent: dict[str, ca.MX], scalars: dict[str, ScalarVar], derivative: dict[str, ca.MX],
             system: tuple[Any, list[tuple[ca.MX, str]], list[ca.MX]]) -> ca.MX:
    """The time derivative of the unknown *name*, with those of the unknowns its block needs (added to
    *tangent*, which starts with the states' and time's), block by block in the model's order: a block
    r(z, y) = 0 in its unknowns z gives dz = -(dr/dz)^-1 (dr/dy dy), dy the derivatives of the states (their
    symbols), of time (1) and of the unknowns of earlier blocks; parameters and discrete variables have
    none (constant between events)."""
    blocks, residuals, unknowns = system
    block_of = {u.name(): k for k, b in enumerate(blocks) for u in (unknowns[j] for j in b.unknowns)}
    inputs = {n for n, sv in scalars.items() if sv.kind == "input"}
    state_ders = {d.name(): n for n, d in derivative.items()}
    needed: set[int] = set()
    stack = [block_of[name]] if name in block_of else []
    while stack:
        k = stack.pop()
        if k in needed or all(unknowns[j].name() in tangent for j in blocks[k].unknowns):
            continue
        needed.add(k)
        for i in blocks[k].equations:
            for v in ca.symvar(residuals[i][0]):
                if v.name() in block_of and block_of[v.name()] != k:
                    stack.append(block_of[v.name()])
    for k in sorted(needed):
        res = ca.vertcat(*(residuals[i][0] for i in blocks[k].equations))
        unk = [unknowns[j] for j in blocks[k].unknowns]
        taken = {u.name() for u in unk}
        for u in unk:
            if u.name() in state_ders:
                raise InitialDerivativeError(name, f"{name} depends on der({state_ders[u.name()]}), "
                                             "whose derivative the model does not give")
        ys = [v for v in ca.symvar(res) if v.name() not in taken]
        held = sorted(v.name() for v in ys if v.name() in inputs)
        if held:
            raise InitialDerivativeError(name, f"{name} depends on the input {held[0]}, whose "
                                         "derivative the FMU is not given")
        ys = [v for v in ys if v.name() in tangent]
        if not ys:
            change = ca.MX.zeros(len(unk), 1)
        else:
            rate = ca.jtimes(res, ca.vertcat(*ys), ca.vertcat(*(tangent[v.name()] for v in ys)))
            jac = ca.jacobian(res, ca.vertcat(*unk))
            change = -rate / jac if len(unk) == 1 else -ca.solve(jac, rate)
        for i, u in enumerate(unk):
            tangent[u.name()] = change[i]
    return tangent.get(name, ca.MX(0.0))


def with_initial_derivatives(tr: Any, residuals: list[tuple[ca.MX, str]], states: list[ScalarVar],
                             system: tuple[Any, list[tuple[ca.MX, str]], list[ca.MX]]) -> list[tuple[ca.MX, str]]:
    """The initial *residuals* of translator *tr* with each ``der(v)`` of a variable that was no state
    (``tr._initial_ders``: name -> (its symbol, the span of the first equation using it)) replaced by its
    value (:func:`derivative_values`); one that has none is refused naming the equation."""
    pending: dict[str, tuple[ca.MX, Any]] = getattr(tr, "_initial_ders", {}) or {}
    if not pending:
        return residuals
    try:
        values = derivative_values(list(pending), tr.scalars, states, tr.der_placeholders, system, tr.time)
    except InitialDerivativeError as exc:
        raise tr.unsupported(f"der({exc.name}) in an initial equation, where {exc.name} is not a state and "
                             f"{exc.why}", r"\bder\s*\(", span=pending[exc.name][1]) from None
    syms = [pending[n][0] for n in values]
    exprs = ca.substitute([r for r, _ in residuals], syms, [values[n] for n in values])
    return [(e, origin) for e, (_, origin) in zip(exprs, residuals)]
