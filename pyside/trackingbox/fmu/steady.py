"""Steady states of stiff models by following their own settling.

A root finder started far from the steady state of a stiff model (vapour
spaces that settle in milliseconds beside tanks that settle in hours) can
stall, or end at a root no run of the model reaches: on the 2-effect
evaporator train, Powell's hybrid method from the model's start values stops
with a vapour mass still moving by 439 times its size per hour, after driving
a condensate tank's dry-solids mass to -4.3 kg, while a plain run of 12 h with
the same inputs ends at a steady state.

:func:`settle_by_integration` runs the model instead, in a time of its own: a
stiff integrator (BDF with error control, scipy's ``solve_ivp``) on the rates
from the current states, until every rate is below the tolerance. The error
control keeps it on the model's trajectory, so it ends at the steady state the
model itself settles to from there (an unstable root Newton's method would
find is passed by); the BDF steps grow as the model settles, so hours of the
slowest tank cost a few hundred steps.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import FMUError

Vector = npt.NDArray[np.float64]

#: the integrator's tolerances on the (scaled) states
RTOL = 1e-6
ATOL = 1e-9


@dataclass(frozen=True)
class Settled:
    """Where :func:`settle_by_integration` ended."""

    #: the last states and their rates
    z: Vector
    rates: Vector
    #: True when ``max |rates| <= tol``
    converged: bool
    #: the integrator's own time at the end and how many rate evaluations it took
    time: float
    evaluations: int
    #: why it did not settle ("" where it did)
    message: str
    #: the states whose rates the model gave as NaN or infinite on the way (their indices; empty where
    #: every rate it gave was finite). The run then ends at the last states with finite rates.
    nonfinite: tuple[int, ...] = ()


def settle_by_integration(f: Callable[[Vector], Vector], z0: npt.ArrayLike, tol: float, *,
                          t_max: float = 1e10) -> Settled:
    """Integrate ``dz/dt = f(z)`` from *z0* until ``max |f(z)| <= tol`` (or *t_max*).

    Parameters
    ----------
    f
        The rates (for a model: its derivatives, scaled as *z* is; states of order 1).
    z0
        The start: the states the model has now.
    tol
        Settled when no rate is larger.
    t_max
        Give up at this time of the integrator's own (a state that integrates, such
        as a level whose flows do not balance, never settles: its rate stays).
    """
    from scipy.integrate import solve_ivp  # 0.03 s more imports than scipy.optimize; only needed here

    count = [0]
    # the last states whose rates were all finite, and where the first non-finite rates were
    last_finite: list[tuple[float, Vector]] = []
    bad: list[int] = []

    def rhs(t: float, z: Vector) -> Vector:
        count[0] += 1
        rates = np.array(f(z), dtype=float)
        if np.all(np.isfinite(rates)):
            last_finite[:] = [(float(t), np.array(z, dtype=float))]
        elif not bad:
            bad.extend(int(i) for i in np.flatnonzero(~np.isfinite(rates)))
        return rates

    def settled(_t: float, z: Vector) -> float:
        count[0] += 1
        worst = float(np.max(np.abs(f(z)), initial=0.0))
        # stop at half the tolerance: the event's states are interpolated between two steps
        return float(np.log(max(worst, 1e-300) / (0.5 * tol))) if np.isfinite(worst) else 1.0

    settled.terminal = True  # type: ignore[attr-defined]
    z = np.array(z0, dtype=float)
    t_end, message = 0.0, ""
    if not np.max(np.abs(rhs(0.0, z)), initial=0.0) <= tol:
        try:
            sol = solve_ivp(rhs, (0.0, float(t_max)), z, method="BDF", rtol=RTOL, atol=ATOL, events=settled)
        except ValueError:
            # scipy refuses to factor a Jacobian holding NaN or infinity ("array must not contain infs or
            # NaNs"): the run reached states where the model's rates are not finite (outside the range its
            # equations hold). It ends at the last states it had finite rates for, and says so.
            if not bad:
                raise
            if last_finite:
                t_end, z = last_finite[0]
            message = (f"its rates became non-finite after {t_end:.3g} s (the run left the range the model's "
                       f"equations hold)")
        else:
            z, t_end = np.array(sol.y[:, -1], dtype=float), float(sol.t[-1])
            message = (f"the integrator failed at {t_end:.3g} s ({' '.join(str(sol.message).split()).rstrip('.')})"
                       if sol.status < 0 else f"still moving after {t_end:.3g} s")
    rates = rhs(t_end, z)
    converged = bool(np.all(np.isfinite(rates)) and np.max(np.abs(rates), initial=0.0) <= tol)
    return Settled(z, rates, converged, t_end, count[0], "" if converged else message,
                   () if converged else tuple(bad))


def no_steady_state(states: Sequence[str], drift: Vector, limit: float, lost: tuple[int, ...], how: str) -> str:
    """Why the states reached are no steady state ("" when they are one), for ``settle``'s error.

    *drift*: each state's rate in its own size per hour there (infinite where the states are not finite);
    *limit*: the largest accepted; *lost*: the states whose rates turned non-finite on the way
    (:attr:`Settled.nonfinite`); *how*: how the search ended.
    """
    def named(i: int) -> str:
        return states[i] if i < len(states) else f"state {i + 1}"

    if lost:
        # the model's own settling leaves the range its equations hold (a plant stopped with its heating on
        # boils dry): there is no steady state to start from at these inputs
        return (f"settling from its states, the derivative of {', '.join(named(i) for i in lost[:5])}"
                f"{' and more' if len(lost) > 5 else ''} became NaN or infinite ({how}); the inputs there may be "
                f"outside where the model operates (a stoppage): start the run at a time the plant runs, or set "
                f"[data] initial = \"model\"")
    if np.all(drift <= limit):
        return ""
    worst = int(np.nanargmax(np.where(np.isfinite(drift), drift, np.inf)))
    return (f"{named(worst)} still changes by {drift[worst]:.3g} times its size per hour ({how}); an integrating "
            f"state (a level whose flows do not balance) has none: set [data] initial = \"model\" to start from "
            f"the FMU's own initial state")


def free_states(names: Sequence[str], hold: Sequence[str], model: str) -> npt.NDArray[np.bool_]:
    """Which of the states *names* a steady start settles: all but those in *hold*, which keep their values.

    A slow state of hours to days (a scale that grows above a dry-solids onset and washes off over a day)
    is no part of the steady state the process reaches in minutes: its value is the plant's history, not
    an equilibrium (:attr:`trackingbox.simulation.windows.Problem.carry`).

    >>> free_states(["T", "R"], ["R"], "m.fmu").tolist()
    [True, False]
    """
    unknown = sorted(set(hold) - set(names))
    if unknown:
        raise FMUError(f"{model}: no continuous state {', '.join(unknown)} to hold in its steady state")
    return np.array([s not in set(hold) for s in names], dtype=bool)


def spread(full: Vector, free: npt.NDArray[np.bool_], values: Vector) -> Vector:
    """*full* with *values* at the positions *free*.

    >>> spread(np.array([1.0, 2.0, 3.0]), np.array([True, False, True]), np.array([7.0, 9.0])).tolist()
    [7.0, 2.0, 9.0]
    """
    out = np.array(full, dtype=float, copy=True)
    out[free] = values
    return out
