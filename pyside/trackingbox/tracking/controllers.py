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

One law in two places, proven equal. The PI parameter controller and the
state compensation are the Modelica blocks ``TrackingBox.Blocks.ParameterController``
and ``TrackingBox.Blocks.StateCompensation`` (continuous laws, no events, so
they compile on the embedded path). :class:`ScaledPI` and
:class:`StateCompensator` are their *exact discretisations* for two error
signals (``interpolation``):

* ``"zoh"``: the error held constant over each sample period; ``update`` at
  ``t_k`` with the error ``e_k`` returns the block's output at ``t_k + Ts``;
* ``"linear"``: the error linear from one sample to the next; ``update`` at
  ``t_k`` integrates ``[t_k - Ts, t_k]`` from ``e_(k-1)`` to ``e_k`` and returns
  the block's output at ``t_k``. This is the signal the block sees in a
  compiled tracking box (measurement interpolated linearly between samples,
  twin output continuous), so the tracking runtime uses it by default: with
  ``"zoh"`` the box's proportional action reacts to each new sample one sample
  before the runtime's, and the two parameter trajectories differ by ``kp``
  times the sample-to-sample change of the error (measurement noise, input
  steps), which is what ``validate`` measured (0.0175 of the bounds on the
  heat-exchanger demo, against 0.0025 with ``"linear"``).

``tests/test_controllers.py`` drives the compiled blocks and these classes with
one error sequence, held and interpolated, and requires the same outputs.

Why a continuous law discretised exactly, and not the textbook discrete
velocity form ``u(k) = u(k-1) + kp (e(k) - e(k-1)) + kp Ts/Ti e(k)``: the
embedded compile path accepts no ``when``, ``pre`` or ``sample``, so the
Modelica block cannot store ``e(k-1)``. It stores instead an *error memory*
``eMem`` that follows the error with a short time constant ``Te`` (a tenth of
the sample time by default), and the proportional action is
``kp (e - eMem)/Te``. Over one sample this moves the output by
``kp (e(k) - eMem(k)) (1 - exp(-Ts/Te))``, which is the velocity form's
``kp (e(k) - e(k-1))`` to within ``exp(-10) = 4.5e-5`` of the step.

Hold (one meaning everywhere): the output is frozen and nothing integrates,
while the error memory keeps following the error, so resuming gives no
proportional kick (bumpless). The Python controllers are held by ``hold=True``
(start-up hold, stoppage, solver recovery) and while the measurement or the
simulated value is missing (NaN); a missing error cannot be followed, so the
memory is then set to the first valid error after the gap. The memory starts
at 0 in both (the embedded path has no initial equations to start it at the
first error): without a start-up hold the first sample gets the proportional
action on the whole initial error; with a start-up hold of a few samples
(``[tracking] hold_until``) the memory settles first and tracking starts
without a kick. The state compensator is the exception: a proportional law
``m = K·eMem``, its memory is frozen with its output (see :class:`StateCompensator`).

Clamp and anti-windup: the output stops at 0 and 100 % while its rate points
out of the range (conditional integration). A saturated controller stores no
hidden integral and leaves the bound as soon as the rate changes sign.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

logger = logging.getLogger(__name__)

Mode = Literal["auto", "hold"]
Interpolation = Literal["zoh", "linear"]

__all__ = ["Scaling", "ScaledPI", "SlidingMode", "StateCompensator", "Mode", "Interpolation", "MEMORY_FRACTION"]

#: Default time constant of the error memory as a fraction of the sample time
#: (``Te = Ts/10``): the proportional step then completes to ``exp(-10)``
#: within one sample.
MEMORY_FRACTION = 0.1


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


class _ErrorMemory:
    """The error memory of the blocks and the bookkeeping of the ``"linear"`` steps.

    :class:`ScaledPI` and :class:`StateCompensator` both follow the error with
    ``dm/dt = (e - m)/Te`` and, with an interpolated error, integrate the span
    since the previous call. This holds that state (memory, previous error and
    hold flag, mode), advances it and saves it.
    """

    te: float
    mode: Mode
    #: name of the output attribute saved with the memory (``u`` or ``m``)
    _output: str
    #: True: the memory is frozen with the output while held or missing (a proportional law, whose
    #: output must stay its gain times the memory); False: it follows the error (bumpless PI)
    _memory_holds: bool = False

    def _init_memory(self) -> None:
        #: error memory: starts at 0 as in the block; None after a missing error
        self.e_mem: float | None = 0.0
        #: "linear" only: the error and the hold flag of the previous call
        #: (None: no previous call, or its error was missing)
        self.e_last: float | None = None
        self.hold_last = True

    def _integrate_linear(self, e0: float, e1: float, m0: float, dt: float) -> None:  # pragma: no cover
        """Advance the output over *dt* s with the error linear from *e0* to *e1* and the memory at *m0*.

        The hook each block fills in with its own exact law (:class:`ScaledPI`, :class:`StateCompensator`);
        this mixin is never used on its own.
        """
        raise NotImplementedError(f"{type(self).__name__} does not define _integrate_linear (a block using "
                                  "_ErrorMemory must)")

    def _advance_linear(self, e: float | None, hold: bool, dt: float) -> None:
        """Move to the call with error *e*, the error linear since the previous one, *dt* s ago.

        :meth:`_integrate_linear` advances the output over that span unless
        it was held. A missing error cannot be followed: the memory restarts
        at the next valid one, and the span after a missing error is frozen.
        """
        e0 = self.e_last
        if e is None:
            if not self._memory_holds:
                self.e_mem = None
        elif e0 is None:
            # first call (the memory is at its start, 0, as the block's at t = 0) or the first valid
            # error after a missing one (nothing to interpolate over the sample: frozen, the memory restarts)
            if self.e_mem is None:
                self.e_mem = e
        else:
            m0 = e0 if self.e_mem is None else self.e_mem
            if not self.hold_last:
                self._integrate_linear(e0, e, m0, dt)
                self.e_mem = _memory_linear(e0, e, m0, dt, self.te)
            elif not self._memory_holds:
                self.e_mem = _memory_linear(e0, e, m0, dt, self.te)
        self.e_last, self.hold_last = e, bool(hold)
        mode: Mode = "hold" if hold or e is None else "auto"
        if mode != self.mode:
            logger.debug("%s: %s", type(self).__name__, mode)
        self.mode = mode

    # -- checkpointing -------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """JSON-serialisable state, for the tracking loop's checkpoints."""
        return {self._output: getattr(self, self._output), "e_mem": self.e_mem, "mode": self.mode,
                "e_last": self.e_last, "hold_last": self.hold_last}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a state produced by :meth:`state_dict`."""
        setattr(self, self._output, float(state[self._output]))
        self.e_mem = None if state["e_mem"] is None else float(state["e_mem"])
        self.mode = state["mode"]
        self.e_last = None if state.get("e_last") is None else float(state["e_last"])
        self.hold_last = bool(state.get("hold_last", True))


class _ScaledOutput:
    """What every parameter controller has: scaling, sample time, direction and a 0-100 % output."""

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
        self.mode: Mode = "hold"

    @property
    def value(self) -> float:
        """The parameter value the controller currently outputs."""
        return self.scaling.to_parameter(self.u)


class _ScaledController(_ScaledOutput):
    """Discrete velocity-form machinery of :class:`SlidingMode`: clamping, hold, bumpless resume.

    Held (NaN or ``hold``), the output is frozen and the error history restarts
    at the next valid sample (no derivative kick on resume).
    """

    def __init__(self, scaling: Scaling, *, ts: float, direction: int, p0: float) -> None:
        super().__init__(scaling, ts=ts, direction=direction, p0=p0)
        #: last error (%) used by the incremental law; None right after a hold
        self.e_prev: float | None = None

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
    def state_dict(self) -> dict[str, Any]:
        """JSON-serialisable state, for the tracking loop's checkpoints."""
        return {"u": self.u, "e_prev": self.e_prev, "mode": self.mode}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a state produced by :meth:`state_dict`."""
        self.u = float(state["u"])
        self.e_prev = None if state["e_prev"] is None else float(state["e_prev"])
        self.mode = state["mode"]


class ScaledPI(_ScaledOutput, _ErrorMemory):
    """PI parameter controller on a 0-100 % output: the exact discretisation of ``ParameterController``.

    The continuous law of ``TrackingBox.Blocks.ParameterController`` is

    ``du/dt = d·kp·(e/Ti + (e - m)/Te)``, ``dm/dt = (e - m)/Te``

    with ``u`` clamped to 0..100 % by conditional integration and frozen on
    hold; ``m`` is the error memory and ``d = ±1`` the direction. For ``e``
    constant over a sample, ``m`` relaxes exactly
    (``m(k+1) = e + (m(k) - e)·exp(-Ts/Te)``) and the unclamped increment is

    ``Δu = d·kp·(Ts/Ti·e + (e - m(k))·(1 - exp(-Ts/Te)))``.

    The rate has at most one sign change within a sample (where
    ``exp(-t/Te) = -Te·e/(Ti·(e - m(k)))``); on each monotone piece the
    clamped integral is the clamped sum, so the update splits the increment
    there and clamps after each piece. This is exact, not an approximation.

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
    te : float, optional
        Time constant of the error memory (s); default ``ts/10``.
    interpolation : {"zoh", "linear"}
        How the error varies between samples. ``"zoh"`` (default): held
        constant over each sample; :meth:`update` at ``t_k`` integrates
        ``[t_k, t_k+1]`` with ``e_k`` and returns the value at ``t_k+1``.
        ``"linear"``: linear from one sample to the next, as the compiled box
        sees a linearly interpolated measurement and a continuous twin output;
        :meth:`update` at ``t_k`` integrates ``[t_k-1, t_k]`` with the error
        going from ``e_k-1`` to ``e_k`` (under the hold given at ``t_k-1``) and
        returns the value at ``t_k``. Both are exact solutions of the block's
        law for their error signal (see :func:`_integrate_clamped_linear`).

    Examples
    --------
    >>> pi = ScaledPI(Scaling(0.0, 10.0, span=2.0), kp=1.0, ti=20.0, ts=10.0, direction=1, p0=5.0)
    >>> pi.update(1.0, 0.8, hold=True)  # start-up hold: frozen, the memory settles on e = 10 %
    5.0
    >>> round(pi.update(1.0, 0.8), 3)   # no proportional kick: Ts/Ti*kp*e = 5 % -> u = 55 %
    5.5

    With ``interpolation="linear"`` the first call only records the error; the
    next integrates the sample between them (error 10 % -> 10 %: the same 5 %):

    >>> lin = ScaledPI(Scaling(0.0, 10.0, span=2.0), kp=1.0, ti=20.0, ts=10.0, direction=1, p0=5.0,
    ...                interpolation="linear")
    >>> lin.update(1.0, 0.8, hold=True), lin.update(1.0, 0.8), round(lin.update(1.0, 0.8), 3)
    (5.0, 5.0, 5.5)
    """

    _output = "u"

    def __init__(self, scaling: Scaling, *, kp: float, ti: float, ts: float, direction: int, p0: float,
                 te: float | None = None, interpolation: Interpolation = "zoh") -> None:
        super().__init__(scaling, ts=ts, direction=direction, p0=p0)
        if not kp > 0.0 or not ti > 0.0:
            raise ValueError(f"PI gains must be positive, got kp={kp}, ti={ti}")
        te = ts * MEMORY_FRACTION if te is None else float(te)
        if not (te > 0.0 and math.isfinite(te)):
            raise ValueError(f"error-memory time constant must be positive, got {te}")
        if interpolation not in ("zoh", "linear"):
            raise ValueError(f"interpolation must be 'zoh' or 'linear', got {interpolation!r}")
        self.kp = float(kp)
        self.ti = float(ti)
        self.te = te
        self.interpolation: Interpolation = interpolation
        self._init_memory()  # error memory (%), previous error and hold flag

    @property
    def lead(self) -> int:
        """Samples by which :meth:`update`'s value leads its call: 1 (``"zoh"``) or 0 (``"linear"``)."""
        return 1 if self.interpolation == "zoh" else 0

    def update(self, setpoint: float | None, process_value: float | None, *, hold: bool = False,
               dt: float | None = None) -> float:
        """Advance one sample and return the parameter value (see *interpolation* for which time).

        Parameters
        ----------
        setpoint : float or None
            The plant measurement; NaN/None puts the controller on hold.
        process_value : float or None
            The twin's simulated sensor; NaN/None puts the controller on hold.
        hold : bool
            Force a hold (start-up, stoppage, flagged data, solver recovery).
        dt : float, optional
            ``"linear"`` only: the time (s) since the previous call, when it is
            not the sample time (the tracking runtime's sub-steps, which
            integrate the controller with the twin over parts of a sample).
        """
        if self.interpolation == "linear":
            return self._update_linear(setpoint, process_value, hold, self.ts if dt is None else float(dt))
        if dt is not None and dt != self.ts:
            raise ValueError(f"interpolation 'zoh' steps one sample time ({self.ts} s), got dt = {dt}")
        if not (_valid(setpoint) and _valid(process_value)):
            if self.mode != "hold":
                logger.debug("ScaledPI: hold (missing value)")
            self.mode = "hold"
            self.e_mem = None  # cannot follow a missing error: restart at the next valid one
            return self.value
        e = self.scaling.error_percent(float(setpoint), float(process_value))  # type: ignore[arg-type]
        m = e if self.e_mem is None else self.e_mem
        if hold:
            if self.mode != "hold":
                logger.debug("ScaledPI: hold")
            self.mode = "hold"
        else:
            self.mode = "auto"
            self.u = _integrate_clamped(self.u, self.direction * self.kp, e / self.ti, e - m, self.ts, self.te)
        self.e_mem = e + (m - e) * math.exp(-self.ts / self.te)
        return self.value

    def _update_linear(self, setpoint: float | None, process_value: float | None, hold: bool, dt: float) -> float:
        """``"linear"``: integrate the *dt* s since the previous call, the error linear between the two."""
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"the time since the previous update must be positive, got dt = {dt}")
        sc = self.scaling
        isfinite = math.isfinite
        # Scaling.error_percent and .to_parameter written out: this runs at every sub-step of every pair
        e = 100.0 * (float(setpoint) - float(process_value)) / sc.span \
            if setpoint is not None and process_value is not None and isfinite(setpoint) \
            and isfinite(process_value) else None  # type: ignore[arg-type]
        self._advance_linear(e, hold, dt)
        return sc.p_min + self.u / 100.0 * (sc.p_max - sc.p_min)

    def _integrate_linear(self, e0: float, e1: float, m0: float, dt: float) -> None:
        self.u = _integrate_clamped_linear(self.u, self.direction * self.kp, self.ti, e0, e1, m0, dt, self.te)


def _integrate_clamped(u: float, gain: float, rate: float, step: float, ts: float, te: float) -> float:
    """Exact end value of ``du/dt = gain·(rate + step/te·exp(-t/te))`` over ``[0, ts]``, clamped to 0..100.

    The clamp is conditional integration (the output stops at a bound while
    the rate points outwards). The rate changes sign at most once; on each
    monotone piece the clamped integral equals the clamped sum.
    """
    a = math.exp(-ts / te)
    total = gain * (rate * ts + step * (1.0 - a))
    if step != 0.0:
        r = -rate * te / step  # exp(-t*/te) at the sign change of the rate
        if a < r < 1.0:
            t_turn = -te * math.log(r)
            first = gain * (rate * t_turn + step * (1.0 - r))
            return _clamp(_clamp(u + first) + (total - first))
    return _clamp(u + total)


def _memory_linear(e0: float, e1: float, m0: float, ts: float, te: float) -> float:
    """Error memory at the end of a sample over which the error goes linearly from *e0* to *e1*.

    ``dm/dt = (e - m)/te`` with ``e = e0 + s·t``: ``m = e - s·te + (m0 - e0 + s·te)·exp(-t/te)``.
    """
    s = (e1 - e0) / ts
    return e1 - s * te + (m0 - e0 + s * te) * math.exp(-ts / te)


def _integrate_clamped_linear(u: float, gain: float, ti: float, e0: float, e1: float, m0: float,
                              ts: float, te: float) -> float:
    """Exact end value of the block's clamped law over one sample with the error linear from *e0* to *e1*.

    With ``e = e0 + s·t`` and the memory ``m`` as in :func:`_memory_linear`,
    ``e - m = s·te + c·exp(-t/te)`` (``c = e0 - m0 - s·te``), so the rate is
    ``gain·g(t)`` with ``g(t) = A + B·t + (c/te)·exp(-t/te)``, ``A = e0/ti + s``,
    ``B = s/ti``, and its integral is ``F(t) = gain·(A·t + B·t²/2 + c·(1 - exp(-t/te)))``.
    ``g`` is convex or concave, so it has at most one extremum and two zeros
    in the sample; between zeros the rate keeps its sign and the clamped
    (conditionally integrated) output is the clamped sum. The zeros are found
    to machine precision (adjacent floating-point numbers around the sign
    change) by :func:`_zero_of_rate`: Newton's method from the end of the
    monotone piece where it converges without overshoot, then a check of the
    sign on the neighbouring floats.
    """
    s = (e1 - e0) / ts
    a_ = e0 / ti + s
    b_ = s / ti
    c = e0 - m0 - s * te
    k = c / te
    exp = math.exp

    t_ext = 0.0  # the extremum of g when it is inside the sample (0: none)
    if k != 0.0:
        r = b_ * te / k  # exp(-t*/te) at the extremum of g
        if 0.0 < r < 1.0:
            t_ext = -te * math.log(r)
            if not t_ext < ts:
                t_ext = 0.0
    # the monotone pieces [0, t_ext], [t_ext, ts] (or [0, ts]); a sign change of g on a piece is a cut
    g_lo = a_ + b_ * 0.0 + k * exp(-0.0 / te)
    g_hi = a_ + b_ * ts + k * exp(-ts / te)
    f_prev = 0.0
    lo = 0.0
    if t_ext > 0.0:
        g_ext = a_ + b_ * t_ext + k * exp(-t_ext / te)
        if g_lo * g_ext < 0.0:
            t = _zero_of_rate(a_, b_, k, te, 0.0, t_ext, g_lo)
            f_prev = gain * (a_ * t + 0.5 * b_ * t * t + c * (1.0 - exp(-t / te)))
            u += f_prev - 0.0
            u = 0.0 if u < 0.0 else 100.0 if u > 100.0 else u
        lo, g_lo = t_ext, g_ext
    if g_lo * g_hi < 0.0:
        t = _zero_of_rate(a_, b_, k, te, lo, ts, g_lo)
        f_t = gain * (a_ * t + 0.5 * b_ * t * t + c * (1.0 - exp(-t / te)))
        u += f_t - f_prev
        u = 0.0 if u < 0.0 else 100.0 if u > 100.0 else u
        f_prev = f_t
    f_t = gain * (a_ * ts + 0.5 * b_ * ts * ts + c * (1.0 - exp(-ts / te)))
    u += f_t - f_prev
    return 0.0 if u < 0.0 else 100.0 if u > 100.0 else u


def _zero_of_rate(a_: float, b_: float, k: float, te: float, lo: float, hi: float, g_lo: float) -> float:
    """The zero of ``g(t) = a_ + b_·t + k·exp(-t/te)`` in ``[lo, hi]``, where ``g`` is monotone and changes sign.

    The answer is what a bisection to machine precision returns: with ``neg(t)`` meaning
    ``g(t) < 0``, the midpoint of the two adjacent floats ``t0 < t1`` with
    ``neg(t0) == neg(lo)`` and ``neg(t1) != neg(lo)``. Newton's method starts
    at the end where ``g·g'' > 0`` (Fourier's condition: ``g`` is convex or
    concave on the piece, so the iterates approach the zero from that side
    without overshooting and converge quadratically); the floats next to the
    last iterate are then searched for the sign change, in steps of 1, 2, 4, ...
    floats (where the terms of ``g`` cancel, rounding makes its sign ragged
    over a few floats), and bisection narrows that bracket to adjacent floats.
    """
    exp, nextafter = math.exp, math.nextafter
    neg_lo = g_lo < 0.0
    # Fourier's condition: g'' = k/te²·exp(-t/te) has the sign of k
    x = lo if (g_lo > 0.0) == (k > 0.0) else hi
    ahead = 1.0 if x == lo else -1.0  # the direction of the iterates
    inv_te = 1.0 / te
    for _ in range(100):
        ex = k * exp(-x * inv_te)
        dg = b_ - ex * inv_te
        if dg == 0.0:
            break
        x_new = x - (a_ + b_ * x + ex) / dg
        if not (x_new - x) * ahead > 0.0:  # at the zero, or rounding turned it back: stop
            break
        x = x_new if lo <= x_new <= hi else min(max(x_new, lo), hi)
    # bracket the sign change next to x: steps of 1, 2, 4, ... ulps away from x's side (rounding
    # makes g's sign ragged over a few ulps where its terms cancel), then bisect to adjacent floats
    if (a_ + b_ * x + k * exp(-x / te) < 0.0) == neg_lo:
        t0, t1, toward = x, hi, hi
    else:
        t0, t1, toward = lo, x, lo
    d = abs(nextafter(x, toward) - x)
    while d > 0.0:
        if toward == hi:
            y = t0 + d
            if y >= t1:
                break
            if (a_ + b_ * y + k * exp(-y / te) < 0.0) != neg_lo:
                t1 = y
                break
            t0 = y
        else:
            y = t1 - d
            if y <= t0:
                break
            if (a_ + b_ * y + k * exp(-y / te) < 0.0) == neg_lo:
                t0 = y
                break
            t1 = y
        d *= 2.0
    for _ in range(200):  # bisection for whatever bracket is left (a no-op once t0, t1 are adjacent)
        mid = 0.5 * (t0 + t1)
        if mid <= t0 or mid >= t1:
            break
        if (a_ + b_ * mid + k * exp(-mid / te) < 0.0) == neg_lo:
            t0 = mid
        else:
            t1 = mid
    return 0.5 * (t0 + t1)


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


class StateCompensator(_ErrorMemory):
    """Direct state compensation: the exact discretisation of ``TrackingBox.Blocks.StateCompensation``.

    A correction flow that keeps a twin level on the plant's. The block's law
    is ``dm/dt = K·(e - eMem)/Te``, ``deMem/dt = (e - eMem)/Te`` with
    ``e = L_meas - L_sim``: ``m`` follows ``K·e`` (from a zero start), lagged
    by ``Te``. For ``e`` constant over a sample (``a = exp(-Ts/Te)``):

    ``m(k+1) = m(k) + K·(e(k) - eMem(k))·(1 - a)``, ``eMem(k+1) = e(k) + (eMem(k) - e(k))·a``

    in kg/s with ``K`` in kg/s per m of level difference. A proportional law,
    because a level is an integrating state and a purely integral correction
    would oscillate without damping. The correction flow is its own recorded
    signal, never a parameter change. Both memories start at zero, as in the
    block.

    Hold: the correction and the memory are frozen together, so that
    ``m = K·eMem`` holds at every time; on release the correction follows
    ``K·e`` again (within ``Te``). While a value is missing (NaN) it is held
    the same way. (A bumpless resume, the memory following the difference
    while the correction is frozen, re-bases the law at every hold: ``m`` stays
    ``K·(e - e_release) + m_held``, a permanent correction flow, a mass source
    in the twin. A missing first sample of a historian export did that on the
    evaporator train: 0.18 kg/s into effect 3 from the first 10 s for the whole
    run, which moved the product flow the fouling of effect 1 was paired on.)

    Parameters
    ----------
    gain : float
        ``K``, kg/s per m, ``> 0`` (positive: a plant level above the twin's
        adds flow into the twin's tank).
    ts : float
        Sample time (s).
    te : float, optional
        Time constant of the error memory (s); default ``ts/10``.
    interpolation : {"zoh", "linear"}
        The difference held over each sample, or linear between samples
        (with :meth:`update` returning the value at the call's time), as for
        :class:`ScaledPI`.

    Examples
    --------
    >>> sc = StateCompensator(2.0, ts=10.0)
    >>> round(sc.update(1.5, 1.0), 6)   # K*e*(1 - exp(-10)) from zero
    0.999955
    """

    _output = "m"
    _memory_holds = True

    def __init__(self, gain: float, *, ts: float, te: float | None = None,
                 interpolation: Interpolation = "zoh") -> None:
        if interpolation not in ("zoh", "linear"):
            raise ValueError(f"interpolation must be 'zoh' or 'linear', got {interpolation!r}")
        if not gain > 0.0:
            raise ValueError(f"state-compensation gain must be positive, got {gain}")
        if not (ts > 0.0 and math.isfinite(ts)):
            raise ValueError(f"sample time must be positive, got {ts}")
        te = ts * MEMORY_FRACTION if te is None else float(te)
        if not (te > 0.0 and math.isfinite(te)):
            raise ValueError(f"error-memory time constant must be positive, got {te}")
        self.gain = float(gain)
        self.ts = float(ts)
        self.te = te
        self.m = 0.0
        self.mode: Mode = "hold"
        self.interpolation: Interpolation = interpolation
        self._init_memory()

    def update(self, measured: float | None, simulated: float | None, *, hold: bool = False) -> float:
        """Advance one sample; return the correction (kg/s) at its end (``"zoh"``) or at this call (``"linear"``)."""
        if self.interpolation == "linear":
            return self._update_linear(measured, simulated, hold)
        if not (_valid(measured) and _valid(simulated)):
            self.mode = "hold"
            return self.m
        e = float(measured) - float(simulated)  # type: ignore[arg-type]
        mem = e if self.e_mem is None else self.e_mem
        a = math.exp(-self.ts / self.te)
        if hold:
            self.mode = "hold"
            self.e_mem = mem
        else:
            self.mode = "auto"
            self.m += self.gain * (e - mem) * (1.0 - a)
            self.e_mem = e + (mem - e) * a
        return self.m

    def _update_linear(self, measured: float | None, simulated: float | None, hold: bool) -> float:
        """The sample since the previous call with the difference linear: ``m += K·(s·Ts + c·(1 - a))``."""
        e = float(measured) - float(simulated) \
            if _valid(measured) and _valid(simulated) else None  # type: ignore[arg-type]
        self._advance_linear(e, hold, self.ts)
        return self.m

    def _integrate_linear(self, e0: float, e1: float, m0: float, dt: float) -> None:
        s = (e1 - e0) / self.ts
        c = e0 - m0 - s * self.te
        self.m += self.gain * (s * self.ts + c * (1.0 - math.exp(-self.ts / self.te)))


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
