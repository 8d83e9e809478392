"""PI tuning of parameter controllers from a first-order step-response model.

The SIMC rules (Skogestad 2003), an IMC-derived set for a first-order plus
dead-time model ``K·exp(-θ s)/(τ s + 1)``:

``Kc = τ / (|K| (τc + θ))``,  ``Ti = min(τ, 4 (τc + θ))``

``τc`` is the desired closed-loop time constant. Here it is chosen relative to
the process: ``τc = lam·τ`` with the pair's ``lambda`` (default 1, a closed loop
as fast as the open loop: conservative, since the measurement is noisy and the
twin must not be shaken). The discrete controller acts through a zero-order
hold, which behaves like a delay of half a sample, so the effective delay is
``θ + Ts/2``.

The controllers work in a scaled domain (see :mod:`.controllers`): output in %
of the parameter range, error in % of the variable span. The process gain in
that domain is ``Ks = K·(p_max - p_min)/span`` and the scaled controller gain
``Kp = τ / (|Ks| (τc + θ))`` is dimensionless. The direction (sign of ``K``) is
handled by the controller, so the gains here are positive.

:func:`variable_span` and :func:`pair_settings` are the one rule that turns a
``[[pairs]]`` entry into controller settings; the Python runtime
(:mod:`.runtime`) and the generated Modelica tracking box
(:mod:`trackingbox.generate`) both use them, so they cannot disagree.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..errors import SpecError
from .controllers import Scaling, direction_from_gain

__all__ = ["PIGains", "ControllerSettings", "simc_pi", "scaled_process_gain", "tune_scaled_pi",
           "variable_span", "pair_settings"]


@dataclass(frozen=True)
class PIGains:
    """PI settings of one parameter controller.

    Attributes
    ----------
    kp : float
        Dimensionless gain in the scaled domain (% output per % error).
    ti : float
        Integral time (s).
    kc : float
        The same gain in engineering units (parameter units per variable unit).
    tau_c : float
        Closed-loop time constant used (s).
    delay : float
        Effective delay used (s).
    """

    kp: float
    ti: float
    kc: float
    tau_c: float
    delay: float


def simc_pi(gain: float, time_constant: float, delay: float = 0.0, *, tau_c: float | None = None) -> tuple[float, float]:
    """SIMC PI settings ``(Kc, Ti)`` for ``K·exp(-θ s)/(τ s + 1)``.

    Parameters
    ----------
    gain : float
        Process gain ``K`` (non-zero); only its magnitude is used.
    time_constant : float
        ``τ`` (s), ``> 0``.
    delay : float
        ``θ`` (s), ``>= 0``.
    tau_c : float, optional
        Closed-loop time constant; default ``τ``.

    Returns
    -------
    kc, ti : float
        ``Kc = τ/(|K|(τc+θ))`` in the units of 1/K, ``Ti = min(τ, 4(τc+θ))`` in s.

    Examples
    --------
    >>> simc_pi(2.0, 100.0, 10.0, tau_c=40.0)
    (1.0, 100.0)
    """
    if not math.isfinite(gain) or gain == 0.0:
        raise ValueError(f"process gain must be finite and non-zero, got {gain}")
    if not time_constant > 0.0:
        raise ValueError(f"time constant must be positive, got {time_constant}")
    if not delay >= 0.0:
        raise ValueError(f"delay must be non-negative, got {delay}")
    tc = time_constant if tau_c is None else float(tau_c)
    if not tc + delay > 0.0:
        raise ValueError("tau_c + delay must be positive")
    kc = time_constant / (abs(gain) * (tc + delay))
    ti = min(time_constant, 4.0 * (tc + delay))
    return kc, ti


def scaled_process_gain(gain: float, scaling: Scaling) -> float:
    """Process gain in the scaled domain: ``K·(p_max - p_min)/span`` (% per %).

    >>> scaled_process_gain(-0.004, Scaling(800.0, 1200.0, span=3.2))
    -0.5
    """
    return gain * (scaling.p_max - scaling.p_min) / scaling.span


def tune_scaled_pi(gain: float, time_constant: float, scaling: Scaling, *, ts: float,
                   lam: float = 1.0, delay: float = 0.0) -> PIGains:
    """SIMC settings for a scaled parameter controller.

    Parameters
    ----------
    gain : float
        Steady-state gain ``d(variable)/d(parameter)`` in engineering units.
    time_constant : float
        Time constant of the step response (s).
    scaling : Scaling
        Parameter bounds and variable span of the controller.
    ts : float
        Controller sample time (s); adds ``ts/2`` to the delay (zero-order hold).
    lam : float
        ``τc/τ``, the desired closed-loop speed relative to the open loop.
    delay : float
        Process delay (s), if known.

    Examples
    --------
    Gain -0.004 K per unit of a parameter bounded to [800, 1200], variable span
    3.2 K: ``Ks = -0.5``. With ``τ = 300 s``, ``Ts = 20 s`` (θ = 10 s) and
    ``lam = 0.3`` (τc = 90 s): ``Kp = 300/(0.5·100) = 6``, ``Ti = min(300, 400)``,
    ``Kc = 6·400/3.2 = 750``.

    >>> g = tune_scaled_pi(-0.004, 300.0, Scaling(800.0, 1200.0, span=3.2), ts=20.0, lam=0.3)
    >>> g.kp, g.ti, g.kc, g.tau_c, g.delay
    (6.0, 300.0, 750.0, 90.0, 10.0)
    """
    if not lam > 0.0:
        raise ValueError(f"lambda must be positive, got {lam}")
    theta = delay + ts / 2.0
    tau_c = lam * time_constant
    ks = scaled_process_gain(gain, scaling)
    kp, ti = simc_pi(ks, time_constant, theta, tau_c=tau_c)
    kc = kp * (scaling.p_max - scaling.p_min) / scaling.span
    return PIGains(kp=kp, ti=ti, kc=kc, tau_c=tau_c, delay=theta)


def variable_span(gain: float, p_min: float, p_max: float) -> float:
    """Range of a tracking variable that normalises its error: ``|gain|·(p_max - p_min)``.

    It is how far the variable moves when the parameter sweeps its bounds, so
    in the scaled domain the process gain is ±1 (% error per % output). There
    is no fallback (a measured range, or 1): a pair always has a gain, and a
    span that depended on the data would make the generated box and the
    runtime disagree.

    Raises
    ------
    ValueError
        If the gain is zero or not finite, or the bounds are not increasing.

    Examples
    --------
    >>> variable_span(-0.004, 800.0, 1200.0)
    1.6
    """
    span = abs(gain) * (p_max - p_min)
    if not (math.isfinite(span) and span > 0.0):
        raise ValueError(f"span must be positive and finite (gain {gain}, bounds [{p_min}, {p_max}])")
    return span


@dataclass(frozen=True)
class ControllerSettings:
    """Settings of one parameter controller, from one ``[[pairs]]`` entry.

    Attributes
    ----------
    scaling : Scaling
        Parameter bounds and the variable span (:func:`variable_span`).
    kp : float
        Dimensionless gain (% output per % error), ``> 0``.
    ti : float
        Integral time (s), ``> 0``.
    direction : int
        ``+1`` direct, ``-1`` reverse action (sign of the pair's gain).
    tuning : str
        How ``kp``/``ti`` were obtained, for logs and generated comments.
    """

    scaling: Scaling
    kp: float
    ti: float
    direction: int
    tuning: str


def pair_settings(pair: Any, p_min: float, p_max: float, *, ts: float, where: str = "the spec") -> ControllerSettings:
    """The controller settings of a ``[[pairs]]`` entry: the one rule for runtime and generated code.

    * span: :func:`variable_span` of the pair's gain and the parameter's bounds;
    * direction: the sign of the gain (:func:`~.controllers.direction_from_gain`);
    * ``kp``/``ti``: the spec's values where given, SIMC (:func:`tune_scaled_pi`
      with the pair's ``lambda``) for the missing ones. ``kp`` is a magnitude:
      the direction comes from the gain alone, so a negative ``kp`` is refused
      rather than silently flipped or ignored.

    Parameters
    ----------
    pair : trackingbox.spec.PairSpec
        The pair (``variable``, ``parameter``, ``gain``, ``time_constant``,
        ``lambda_``, ``kp``, ``ti``).
    p_min, p_max : float
        The parameter's bounds.
    ts : float
        The tracking sample time (s).
    where : str
        Where the pair is written, for error messages (e.g. the spec's file name).

    Raises
    ------
    SpecError
        A non-positive ``kp`` or ``ti``, a zero gain or bounds that give no span.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> pair = SimpleNamespace(variable="TI-102", parameter="hx.kht", gain=-0.005, time_constant=40.0,
    ...                        lambda_=1.0, kp=0.5, ti=None)
    >>> s = pair_settings(pair, 800.0, 1200.0, ts=10.0)
    >>> (s.scaling.span, s.kp, s.ti, s.direction)
    (2.0, 0.5, 40.0, -1)
    """
    label = f"[[pairs]] {pair.variable} -> {pair.parameter} in {where}"
    try:
        span = variable_span(float(pair.gain), p_min, p_max)
        direction = direction_from_gain(float(pair.gain))
    except ValueError as exc:
        raise SpecError(f"{label}: {exc}") from None
    scaling = Scaling(p_min, p_max, span=span)
    for name in ("kp", "ti"):
        value = getattr(pair, name)
        if value is not None and not (math.isfinite(float(value)) and float(value) > 0.0):
            raise SpecError(f"{label}: {name} = {value} must be positive"
                            + (" (kp is a magnitude: the direction comes from the sign of gain)"
                               if name == "kp" else ""))
    if pair.kp is not None and pair.ti is not None:
        return ControllerSettings(scaling, float(pair.kp), float(pair.ti), direction, "from the spec")
    tuned = tune_scaled_pi(float(pair.gain), float(pair.time_constant), scaling, ts=ts, lam=float(pair.lambda_))
    kp = float(pair.kp) if pair.kp is not None else tuned.kp
    ti = float(pair.ti) if pair.ti is not None else tuned.ti
    return ControllerSettings(scaling, kp, ti, direction, f"SIMC, tau_c = {tuned.tau_c:.6g} s")
