"""Parameter controllers and state compensation, stepping in discrete time.

A *parameter controller* has the plant measurement as setpoint, the twin's
simulated sensor as process value and a model parameter as output. All
controllers here work in a scaled domain:

* the output ``u`` is 0-100 % and maps linearly onto the parameter's bounds,
  ``p = p_min + u/100 * (p_max - p_min)``;
* the error is normalised by the tracking variable's range (span),
  ``e = 100 * (setpoint - process_value) / span`` in %,

so the controller gains are dimensionless (% output per % error). The action is
*direct* when the pair's steady-state gain ``d(variable)/d(parameter)`` is
positive (a measurement above the simulation raises the parameter) and *reverse*
when it is negative.

Every controller can be *held*: while the measurement is missing (NaN), flagged
(masked by a data rule, stoppage) or the start-up hold is on, the output is
frozen and nothing integrates. On the first valid sample after a hold the error
history is reset to the current error, so the proportional term sees no jump
(bumpless resume, no derivative kick).

Anti-windup: both controllers are in *velocity* (incremental) form and apply
each increment to the previous, already clamped output. A clamped output
therefore stores no hidden integral; when the error changes sign the output
leaves the bound on the very next step. No separate anti-windup logic is
needed (this is the classic argument for the velocity form).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

logger = logging.getLogger(__name__)

Mode = Literal["auto", "hold"]

__all__ = ["Scaling", "ScaledPI", "SlidingMode", "StateCompensator", "Mode"]


@dataclass(frozen=True)
class Scaling:
    """Map between engineering units and the controllers' scaled 0-100 % domain.

    Parameters
    ----------
    p_min, p_max : float
        Bounds of the tracking parameter; 0 % is ``p_min``, 100 % is ``p_max``.
    span : float
        Range of the tracking variable used to normalise the error (engineering
        units of the variable); an error of one ``span`` is 100 %.
    """

    p_min: float
    p_max: float
    span: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.p_min) and math.isfinite(self.p_max)) or self.p_max <= self.p_min:
            raise ValueError(f"parameter bounds must be finite with min < max, got [{self.p_min}, {self.p_max}]")
        if not math.isfinite(self.span) or self.span <= 0.0:
            raise ValueError(f"variable span must be finite and positive, got {self.span}")

    def to_percent(self, p: float) -> float:
        """Parameter value -> output in % (not clamped)."""
        return 100.0 * (p - self.p_min) / (self.p_max - self.p_min)

    def to_parameter(self, u: float) -> float:
        """Output in % -> parameter value."""
        return self.p_min + u / 100.0 * (self.p_max - self.p_min)

    def error_percent(self, setpoint: float, process_value: float) -> float:
        """Normalised control error ``100 (setpoint - process_value) / span``."""
        return 100.0 * (setpoint - process_value) / self.span


def _clamp(u: float, lo: float = 0.0, hi: float = 100.0) -> float:
    return lo if u < lo else hi if u > hi else u


def _valid(x: float | None) -> bool:
    return x is not None and math.isfinite(x)


class _ScaledController:
    """Shared machinery: scaling, direction, clamping, hold and bumpless resume."""

    def __init__(self, scaling: Scaling, *, ts: float, direction: int, p0: float) -> None:
        if ts <= 0.0 or not math.isfinite(ts):
            raise ValueError(f"sample time must be positive, got {ts}")
        if direction not in (1, -1):
            raise ValueError(f"direction must be +1 (direct) or -1 (reverse), got {direction}")
        self.scaling = scaling
        self.ts = float(ts)
        self.direction = int(direction)
        #: controller output, % of the parameter range, always within [0, 100]
        self.u = _clamp(scaling.to_percent(p0))
        #: last error (%) used by the incremental law; None right after a hold
        self.e_prev: float | None = None
        self.mode: Mode = "hold"

    @property
    def value(self) -> float:
        """The parameter value the controller currently outputs."""
        return self.scaling.to_parameter(self.u)

    def update(self, setpoint: float | None, process_value: float | None, *, hold: bool = False) -> float:
        """Advance one sample and return the new parameter value.

        Parameters
        ----------
        setpoint : float or None
            The plant measurement; NaN/None puts the controller on hold.
        process_value : float or None
            The twin's simulated sensor; NaN/None puts the controller on hold.
        hold : bool
            Force a hold (start-up, stoppage, flagged data, solver recovery).
        """
        if hold or not (_valid(setpoint) and _valid(process_value)):
            if self.mode != "hold":
                logger.debug("%s: hold", type(self).__name__)
            self.mode = "hold"
            self.e_prev = None  # bumpless: history restarts on resume
            return self.value
        e = self.scaling.error_percent(float(setpoint), float(process_value))  # type: ignore[arg-type]
        if self.e_prev is None:  # resume after hold (or first sample): no derivative kick
            self.e_prev = e
        self.mode = "auto"
        du = self._increment(e, self.e_prev)
        self.u = _clamp(self.u + self.direction * du)
        self.e_prev = e
        return self.value

    def _increment(self, e: float, e_prev: float) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    # -- checkpointing -------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """JSON-serialisable state, for checkpoints."""
        return {"u": self.u, "e_prev": self.e_prev, "mode": self.mode}

    def restore(self, state: dict[str, Any]) -> None:
        """Restore a state produced by :meth:`state`."""
        self.u = float(state["u"])
        self.e_prev = None if state["e_prev"] is None else float(state["e_prev"])
        self.mode = state["mode"]

    def state_dict(self) -> dict[str, Any]:
        """The controller's own state, for the tracking loop's checkpoints (as :meth:`state`)."""
        return self.state()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a state produced by :meth:`state_dict`."""
        self.restore(state)


class ScaledPI(_ScaledController):
    """PI parameter controller in velocity form on a 0-100 % output.

    ``u(k) = clamp(u(k-1) + d·[Kp·(e(k) - e(k-1)) + Kp·Ts/Ti·e(k)], 0, 100)``
    with ``d = +1`` (direct) or ``-1`` (reverse acting) and ``e`` in % of the
    variable's span.

    Parameters
    ----------
    scaling : Scaling
        Parameter bounds and variable span.
    kp : float
        Dimensionless proportional gain (% output per % error), ``> 0``.
    ti : float
        Integral time (s), ``> 0``.
    ts : float
        Sample time (s).
    direction : int
        ``+1`` for a positive pair gain, ``-1`` for a negative one
        (see :func:`direction_from_gain`).
    p0 : float
        Initial parameter value (clamped into the bounds).

    Examples
    --------
    >>> pi = ScaledPI(Scaling(0.0, 10.0, span=2.0), kp=1.0, ti=20.0, ts=10.0, direction=1, p0=5.0)
    >>> pi.update(1.0, 0.8)   # e = 10 %: Kp*Ts/Ti*e = 5 % -> u = 55 %
    5.5
    """

    def __init__(self, scaling: Scaling, *, kp: float, ti: float, ts: float, direction: int, p0: float) -> None:
        super().__init__(scaling, ts=ts, direction=direction, p0=p0)
        if not kp > 0.0 or not ti > 0.0:
            raise ValueError(f"PI gains must be positive, got kp={kp}, ti={ti}")
        self.kp = float(kp)
        self.ti = float(ti)

    def _increment(self, e: float, e_prev: float) -> float:
        return self.kp * (e - e_prev) + self.kp * self.ts / self.ti * e


class SlidingMode(_ScaledController):
    """Sliding-mode parameter controller with a boundary layer.

    In the spirit of Ruusu et al. (2017): the integral term of a PI parameter
    controller can drive the twin unstable when tuned poorly, so the parameter
    moves at a bounded rate towards the sliding surface
    ``s(k) = e(k) + lam·(e(k) - e(k-1))/Ts`` (``lam`` in s).
    The increment is

    ``u(k) = clamp(u(k-1) + d·Ts·eta·sat(s(k)/phi), 0, 100)``

    where ``eta`` (%/s) is the reaching rate and ``sat`` the unit saturation.
    The boundary layer ``|s| < phi`` (%) replaces the discontinuous ``sign`` to
    avoid chattering; inside it the law is linear and equals a velocity-form
    PI with ``Kp = eta·lam/phi`` and ``Ti = lam``. Outside it the parameter
    changes at most ``eta`` % of its range per second, whatever the error.

    Parameters
    ----------
    scaling : Scaling
    eta : float
        Reaching rate, % of the parameter range per second, ``> 0``.
    phi : float
        Boundary-layer half-width, % of the variable span, ``> 0``.
    lam : float
        Surface time constant (s), ``>= 0``.
    ts, direction, p0
        As for :class:`ScaledPI`.
    """

    def __init__(self, scaling: Scaling, *, eta: float, phi: float, lam: float, ts: float,
                 direction: int, p0: float) -> None:
        super().__init__(scaling, ts=ts, direction=direction, p0=p0)
        if not eta > 0.0 or not phi > 0.0 or not lam >= 0.0:
            raise ValueError(f"sliding-mode settings must be eta>0, phi>0, lam>=0; got {eta}, {phi}, {lam}")
        self.eta = float(eta)
        self.phi = float(phi)
        self.lam = float(lam)

    @classmethod
    def from_pi(cls, scaling: Scaling, *, kp: float, ti: float, ts: float, direction: int, p0: float,
                phi: float = 5.0) -> SlidingMode:
        """The sliding-mode controller that equals a given PI inside its boundary layer."""
        return cls(scaling, eta=kp * phi / ti, phi=phi, lam=ti, ts=ts, direction=direction, p0=p0)

    def _increment(self, e: float, e_prev: float) -> float:
        s = e + self.lam * (e - e_prev) / self.ts
        return self.ts * self.eta * _clamp(s / self.phi, -1.0, 1.0)


class StateCompensator:
    """Direct state compensation: a correction flow that keeps a twin level on the plant's.

    ``m(k) = m(k-1) + K·(e(k) - e(k-1)) + K·Ts/Ti·e(k)``,  ``e = L_meas - L_sim``

    in kg/s with ``K`` in kg/s per m of level difference. With ``ti=None`` the
    integral part is off and the law is proportional, ``m = K·e`` (plus the
    value held from before a hold); this is the safe default because a level
    is an integrating state, so a purely integral correction
    (``m(k+1) = m(k) + K·e(k)``) would oscillate without damping. The
    correction flow is its own recorded signal, never a parameter change.

    Parameters
    ----------
    gain : float
        ``K``, kg/s per m, ``> 0`` (positive: a plant level above the twin's
        adds flow into the twin's tank).
    ts : float
        Sample time (s).
    ti : float or None
        Integral time (s) or None for proportional only.
    limit : float or None
        Optional bound on ``|m|`` (kg/s).
    """

    def __init__(self, gain: float, *, ts: float, ti: float | None = None, limit: float | None = None) -> None:
        if not gain > 0.0:
            raise ValueError(f"state-compensation gain must be positive, got {gain}")
        if ti is not None and not ti > 0.0:
            raise ValueError(f"integral time must be positive, got {ti}")
        self.gain = float(gain)
        self.ts = float(ts)
        self.ti = None if ti is None else float(ti)
        self.limit = None if limit is None else abs(float(limit))
        self.m = 0.0
        self.e_prev: float | None = None
        self.mode: Mode = "hold"
        self.started = False

    def update(self, measured: float | None, simulated: float | None, *, hold: bool = False) -> float:
        """Advance one sample; return the correction flow (kg/s). Holds on NaN or ``hold``."""
        if hold or not (_valid(measured) and _valid(simulated)):
            self.mode = "hold"
            self.e_prev = None
            return self.m
        e = float(measured) - float(simulated)  # type: ignore[arg-type]
        if self.e_prev is None:
            # first sample: m = K*e from zero; resume after a hold: bumpless, the
            # held flow is the starting point and the history restarts at e
            self.e_prev = e if self.started else 0.0
        self.started = True
        self.mode = "auto"
        dm = self.gain * (e - self.e_prev)
        if self.ti is not None:
            dm += self.gain * self.ts / self.ti * e
        m = self.m + dm
        if self.limit is not None:
            m = max(-self.limit, min(self.limit, m))
        self.m = m
        self.e_prev = e
        return self.m

    def state(self) -> dict[str, Any]:
        """JSON-serialisable state, for checkpoints."""
        return {"m": self.m, "e_prev": self.e_prev, "mode": self.mode, "started": self.started}

    def restore(self, state: dict[str, Any]) -> None:
        """Restore a state produced by :meth:`state`."""
        self.m = float(state["m"])
        self.e_prev = None if state["e_prev"] is None else float(state["e_prev"])
        self.mode = state["mode"]
        self.started = bool(state["started"])

    def state_dict(self) -> dict[str, Any]:
        """The compensator's own state, for the tracking loop's checkpoints (as :meth:`state`)."""
        return self.state()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a state produced by :meth:`state_dict`."""
        self.restore(state)


def direction_from_gain(gain: float) -> int:
    """Controller direction from the pair's steady-state gain.

    A positive gain ``d(variable)/d(parameter)`` gives direct action (+1), a
    negative one reverse action (-1).

    >>> direction_from_gain(-0.004)
    -1
    """
    if not math.isfinite(gain) or gain == 0.0:
        raise ValueError(f"pair gain must be finite and non-zero, got {gain}")
    return 1 if gain > 0 else -1
