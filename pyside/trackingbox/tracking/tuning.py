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
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .controllers import Scaling

__all__ = ["PIGains", "simc_pi", "scaled_process_gain", "tune_scaled_pi"]


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
