"""Integer and Boolean parameters that the embedded path evaluates at translation (their values
decide equations, array sizes and branches), where their value is not a literal binding.

* :func:`initial_definition`: a ``parameter Integer seed(fixed = false)`` without a binding that an
  initial equation ``seed = expression`` gives (``Modelica.Blocks.Noise.GlobalSeed``'s ``seed`` and
  ``id_impure``, ``PartialNoise``'s ``localSeed``) takes that expression's value.
* :func:`evaluated_from_parameters`: a Boolean or Integer parameter bound to an expression of Real
  parameters (``Modelica.Blocks.Continuous.Derivative``'s ``zeroGain = abs(k) <
  Modelica.Constants.eps``) is evaluated with those parameters at their values, as the tools that
  export FMUs evaluate it; the FMU then checks, with an assert of level error, that the binding
  still gives that value for the parameters it is started with, and stops naming the parameter
  where they were changed so that it would not (the model must then be compiled again).
"""
from __future__ import annotations

from typing import Any

import casadi as ca

from ..errors import CompileError
from .flat_model import Assertion, ScalarVar


def initial_definition(flat: dict, name: str) -> Any:
    """The right-hand side of the initial equation ``name = expression`` in the flat model, or None."""
    for eq in flat.get("initial_equations") or []:
        sub = (eq.get("residual") or {}).get("Binary") or {}
        ref = (sub.get("lhs") or {}).get("VarRef") or {}
        if sub.get("op") == "Sub" and not ref.get("subscripts") and (ref.get("name") or {}).get("name") == name:
            return sub.get("rhs")
    return None


def evaluated_from_parameters(translator, sv: ScalarVar, value: Any) -> float | None:
    """The number *value* (an expression of *sv*'s binding) takes with every parameter it reads at
    its value, with the assert that keeps it so (see the module's docstring); None where *value*
    reads anything but parameters."""
    if not isinstance(value, ca.MX):
        return None
    params = []
    for sym in ca.symvar(value):
        other = translator.scalars.get(sym.name())
        if other is None or other.kind != "parameter":
            return None
        params.append(sym.name())
    try:
        number = translator.numeric(value, f"binding of {sv.name}")
    except CompileError:
        return None
    holds = ca.fabs(value - number) <= 1e-9 * max(1.0, abs(number))
    translator.asserts.append(Assertion(
        condition=ca.if_else(holds, 1.0, 0.0),
        message=(f"parameter {sv.name} was evaluated to {number:g} when the model was compiled (from "
                 f"{', '.join(sorted(params))}); the values it starts with give another value: compile "
                 f"the model again with them"),
        level="error", origin=f"binding of parameter {sv.name}"))
    return number
