"""Exact output sensitivities of an FMU run w.r.t. tunable parameters (forward sensitivity equations).

One integration gives the outputs *and* their derivatives w.r.t. the chosen
parameters: CVODE integrates the states together with

``dS/dt = (df/dx) S + df/dp``  (one block per parameter),

and at every output time ``dy/dp = (dy/dx) S + dy/dp``, where every product
with a Jacobian is one call of the FMU's directional derivative
(``fmi3GetDirectionalDerivative`` / ``fmi2GetDirectionalDerivative``), seeded on
the states and on one parameter (:class:`trackingbox.fmu.SensitivityStepper`).
Nothing is differenced: the only errors are the integrator's, which controls the
sensitivities' local error as it controls the states' (same relative
tolerance; absolute tolerance from the states' nominals, the sensitivities
being scaled by each parameter's range).

The estimation's refinement uses this for its Jacobian
(:func:`trackingbox.estimation.estimate` with ``jacobian="exact"`` or
``"auto"``); :func:`support` says whether an FMU can: it needs the
model-exchange interface with directional derivatives, no parameter-dependent
initial unknowns, and the FMU must accept parameters as knowns, which is checked
once against a central difference of the state derivatives at the start point.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .errors import FMUError, SimulationError, TrackingError
from .fmu import directional_derivatives_reason

log = logging.getLogger(__name__)

#: Largest mismatch (relative to the larger vector) accepted between the FMU's ``d(der x)/dp``
#: and a central difference with a step of 1e-6 of the parameter's scale, when checking that
#: the FMU accepts parameters as knowns. A central difference of smooth double-precision code at
#: that step is good to ~1e-8 relative; an FMU that ignores the parameter seed shows 1.
CHECK_TOLERANCE = 1.0e-4


@dataclass(frozen=True)
class SensitivityRun:
    """Outputs and their parameter sensitivities on a time grid.

    Attributes
    ----------
    time
        Output times (s).
    outputs
        Variable name -> values at :attr:`time`.
    sensitivities
        Variable name -> ``d value / d parameter``, shape ``(len(time), len(parameters))``.
    parameters
        The parameters, in column order.
    directional_calls
        Directional-derivative calls the run made.
    """

    time: np.ndarray
    outputs: dict[str, np.ndarray]
    sensitivities: dict[str, np.ndarray]
    parameters: tuple[str, ...]
    directional_calls: int

    def to_json(self) -> dict[str, Any]:
        """Summary: the grid's extent, the parameters, the call count."""
        return {"parameters": list(self.parameters), "points": int(self.time.size),
                "start": float(self.time[0]) if self.time.size else None,
                "stop": float(self.time[-1]) if self.time.size else None,
                "directional_calls": int(self.directional_calls)}


@dataclass(frozen=True)
class Support:
    """Whether a twin can give exact sensitivities w.r.t. some parameters, and why not.

    Attributes
    ----------
    exact
        True when the FMU's directional derivatives can be used.
    reason
        Why not (empty when *exact*).
    mismatch
        Per parameter, the checked mismatch of ``d(der x)/dp`` against a central
        difference (empty when the check did not run).
    """

    exact: bool
    reason: str = ""
    mismatch: dict[str, float] | None = None

    def to_json(self) -> dict[str, Any]:
        """``{"exact": ..., "reason": ..., "mismatch": {...}}``."""
        return {"exact": self.exact, "reason": self.reason, "mismatch": dict(self.mismatch or {})}


def support(model: Any, names: Sequence[str], scales: Sequence[float], *,
            start_time: float = 0.0, parameters: Mapping[str, float] | None = None,
            inputs: pd.DataFrame | None = None) -> Support:
    """Can *model* (an open :class:`~trackingbox.fmu.FMUModel`) give exact sensitivities w.r.t. *names*?

    First what the model description says
    (:func:`trackingbox.fmu.directional_derivatives_reason`); then, at the
    initial point of a run with *parameters* and *inputs*, the FMU's derivative
    of the state derivatives w.r.t. each parameter is compared with a central
    difference (:data:`CHECK_TOLERANCE`): an FMU that exports derivatives w.r.t.
    states and inputs only, or refuses parameters as knowns, fails here.
    """
    reason = directional_derivatives_reason(model.info, model.interface)
    if reason is not None:
        return Support(False, reason)
    try:
        stepper = model.sensitivity_stepper(names, scales, start_time=start_time, parameters=parameters,
                                            inputs=inputs)
        mismatch = stepper.check_parameter_derivatives()
    except TrackingError as exc:
        return Support(False, f"{model.path.name}: directional derivatives w.r.t. parameters failed ({exc})")
    bad = {n: v for n, v in mismatch.items() if not (v <= CHECK_TOLERANCE)}
    if bad:
        worst = max(bad, key=lambda n: bad[n] if math.isfinite(bad[n]) else math.inf)
        return Support(False, f"{model.path.name}: its directional derivative of the state derivatives w.r.t. "
                              f"{worst} differs from a central difference by {bad[worst]:.3g} of its size "
                              f"(at most {CHECK_TOLERANCE:g}): parameters are not usable as knowns", mismatch)
    return Support(True, "", mismatch)


def simulate_sensitivities(model: Any, *, wrt: Sequence[str], scales: Sequence[float], start_time: float = 0.0,
                           stop_time: float, output_interval: float, inputs: pd.DataFrame | None = None,
                           parameters: Mapping[str, float] | None = None,
                           outputs: Sequence[str]) -> SensitivityRun:
    """Simulate as :meth:`FMUModel.simulate` does and return the outputs' sensitivities w.r.t. *wrt*.

    Parameters
    ----------
    model
        An open :class:`~trackingbox.fmu.FMUModel` (model exchange).
    wrt
        Tunable parameters to differentiate with respect to.
    scales
        One positive scale per parameter (e.g. its bound range): the
        sensitivity equations are integrated for ``dx/dp * scale``, so that the
        integrator's absolute tolerance (the states' nominals) fits them.
    start_time, stop_time, output_interval, inputs, parameters
        As :meth:`FMUModel.simulate` (same communication points: the output
        grid and every input sample time).
    outputs
        Variables to record.

    Raises
    ------
    FMUError
        Unknown names, a co-simulation FMU, no states.
    SimulationError
        The solver failed or produced non-finite values; names the time.
    """
    start_time, stop_time, output_interval = float(start_time), float(stop_time), float(output_interval)
    if not (math.isfinite(start_time) and math.isfinite(stop_time)) or stop_time < start_time:
        raise FMUError(f"stop time {stop_time} must not be before start time {start_time}")
    if not (output_interval > 0 and math.isfinite(output_interval)):
        raise FMUError(f"output interval must be a positive number, not {output_interval}")
    names = list(outputs)
    n = int(math.floor((stop_time - start_time) / output_interval + 1e-9))
    grid = start_time + output_interval * np.arange(n + 1)
    if grid[-1] < stop_time - 1e-9 * max(1.0, abs(stop_time)):
        grid = np.append(grid, stop_time)
    stepper = model.sensitivity_stepper(wrt, scales, start_time=start_time, parameters=parameters, inputs=inputs)
    points = grid
    input_times = stepper.input_times
    if input_times is not None and input_times.size:
        extra = input_times[(input_times > start_time) & (input_times < stop_time)]
        points = np.union1d(grid, extra)
    record = np.isin(points, grid)
    m = len(wrt)
    values = np.empty((grid.size, len(names)))
    sens = np.empty((grid.size, len(names), m))
    read = stepper.reader(names)
    j = 0
    for t, keep in zip(points, record):
        stepper.step(float(t))
        if keep:
            values[j] = read()
            sens[j] = stepper.output_sensitivities(names)
            j += 1
    bad = ~(np.isfinite(values).all(axis=1) & np.isfinite(sens).all(axis=(1, 2)))
    if bad.any():
        i = int(np.argmax(bad))
        raise SimulationError(f"sensitivity run of {Path(model.path).name} produced non-finite values "
                              f"at t = {grid[i]:g} s")
    return SensitivityRun(time=grid, outputs={name: values[:, k] for k, name in enumerate(names)},
                          sensitivities={name: sens[:, k, :] for k, name in enumerate(names)},
                          parameters=tuple(wrt), directional_calls=stepper.directional_calls)
