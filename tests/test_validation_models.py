"""Validation models simulated and checked against what their Documentation promises.

* ``Blocks.Validation.PIHoldAndLimits``: the trajectory against an independent
  integration (scipy) of the law its block's Documentation states, and the
  closed forms of the first-order process while the output is held or at its
  limit.
* ``Fluid.Validation.HeatedLoop``: the loop's flow against a hand balance of
  the pump, pipe and valve curves with the tank's hydrostatic head, a level
  that does not move (a closed loop has no net flow), and the heat balance
  its Documentation states, over one period of the pump's speed once the loop
  has settled.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from trackingbox.fmu import FMUModel

pytestmark = pytest.mark.compile


# ---------------------------------------------------------------- PIHoldAndLimits

K, TI, TT, TF, Y0, TAU = 2.0, 50.0, 10.0, 1.0, 0.2, 60.0  # the model's modifiers and its process


def _pi_reference(t_eval: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Documentation's law integrated by scipy, piece by piece between the switches at 200, 600, 900 s.

    ``e = r - x``, ``Tf der(eF) = e - eF``, ``yUnsat = k eF + yI``,
    ``der(yI) = k e/Ti + (y - yUnsat)/Tt``, ``y = min(max(yUnsat, 0), 1)``;
    both derivatives are zero while held; ``60 der(x) = y - x``.
    """
    def rhs(r: float, held: bool):
        def f(_t: float, s: np.ndarray) -> list[float]:
            x, ef, yi = s
            e = r - x
            y_uns = K * ef + yi
            y = min(max(y_uns, 0.0), 1.0)
            if held:
                return [(y - x) / TAU, 0.0, 0.0]
            return [(y - x) / TAU, (e - ef) / TF, K * e / TI + (y - y_uns) / TT]
        return f

    pieces = [(0.0, 200.0, 0.5, False), (200.0, 600.0, 0.9, False), (600.0, 900.0, 0.9, True),
              (900.0, 1500.0, 0.9, False)]
    state = np.array([0.0, 0.0, Y0])
    xs, ys = np.full(t_eval.size, np.nan), np.full(t_eval.size, np.nan)
    for a, b, r, held in pieces:
        inside = (t_eval >= a) & (t_eval <= b)
        sol = solve_ivp(rhs(r, held), (a, b), state, method="LSODA", t_eval=t_eval[inside], rtol=1e-11,
                        atol=1e-12, max_step=0.5)
        xs[inside] = sol.y[0]
        ys[inside] = np.clip(K * sol.y[1] + sol.y[2], 0.0, 1.0)
        end = solve_ivp(rhs(r, held), (a, b), state, method="LSODA", rtol=1e-11, atol=1e-12, max_step=0.5)
        state = end.y[:, -1]
    return xs, ys


def test_pi_hold_and_limits_against_an_independent_integration_and_closed_forms(fmu_cache) -> None:
    fmu = fmu_cache("TrackingBox.Blocks.Validation.PIHoldAndLimits")
    with FMUModel(fmu, tolerance=1e-9) as model:
        df = model.simulate(stop_time=1500.0, output_interval=1.0, outputs=["con.y", "x"])
    t, y, x = df["time"].to_numpy(), df["con.y"].to_numpy(), df["x"].to_numpy()
    x_ref, y_ref = _pi_reference(t)
    # the FMU crosses the three unevented switches with its error control only (no event), which
    # costs it about the solver's tolerance times the size of the jump; 1e-4 of the unit range
    # is two decades above that and far below any change of gain, time or limit (k 10 % off: 1e-2)
    assert np.abs(x - x_ref).max() < 1e-4, np.abs(x - x_ref).max()
    assert np.abs(y - y_ref).max() < 1e-4, np.abs(y - y_ref).max()

    # the Documentation: the loop settles (x on the setpoint 0.9 with the output below its limit 1)
    assert x[t == 599.0][0] == pytest.approx(0.9, abs=2e-3) and y[t == 599.0][0] < 1.0
    # the setpoint step asks for k 0.4 + 0.5 = 1.3: the output sits at 1, and while it does the
    # process is a free first-order response to 1: x(t) = 1 + (x(ta) - 1) exp(-(t - ta)/60)
    at_limit = np.flatnonzero((t > 200.0) & (y >= 1.0 - 1e-9))
    assert at_limit.size > 20
    ta, tb = int(at_limit[0]), int(at_limit[-1])
    assert np.all(np.diff(at_limit) == 1)  # one stretch at the limit
    closed = 1.0 + (x[ta] - 1.0) * np.exp(-(t[ta:tb + 1] - t[ta]) / TAU)
    assert np.abs(x[ta:tb + 1] - closed).max() < 1e-5
    # held 600-900 s: the output frozen, the process relaxes to it: x = y600 + (x600 - y600) exp(-(t-600)/60)
    i600, i900 = int(np.flatnonzero(t == 601.0)[0]), int(np.flatnonzero(t == 899.0)[0])
    yh = y[i600]
    assert np.ptp(y[i600:i900 + 1]) < 1e-5
    closed = yh + (x[i600] - yh) * np.exp(-(t[i600:i900 + 1] - t[i600]) / TAU)
    assert np.abs(x[i600:i900 + 1] - closed).max() < 1e-5
    # released: no bump (the output continues from its held value) and the loop returns to 0.9
    assert abs(y[t == 901.0][0] - yh) < 2e-3
    assert x[-1] == pytest.approx(0.9, abs=2e-3)


# ---------------------------------------------------------------- HeatedLoop

G = 9.81


def _loop_flow(speed: float, rho: float, level: float) -> float:
    """Mass flow at which the pump's rise equals pipe, valve and the tank's head (the modifiers of HeatedLoop).

    Pump: ``dp = 40 kPa (1.5 s^2 - 0.5 x |x|)``, ``x = m/(rho 8e-5)``; pipe ``dp = 1e6 0.005 (m/0.08)^2``;
    valve (Kv 1, 80 % open, leakage 1e-4): ``m = rho/3600 Kv y dp / (dp^2 + 100^2)^(1/4) / sqrt(1e5)``;
    head: the loop returns to the inlet 1.5 m above the bottom, the pump draws at the level.
    """
    kv_open = 1.0 * (1e-4 + (1 - 1e-4) * 0.8)

    def valve_dp(m: float) -> float:
        return brentq(lambda dp: rho / 3600.0 * kv_open * dp / (dp * dp + 100.0 ** 2) ** 0.25 / math.sqrt(1e5) - m,
                      0.0, 1e7, xtol=1e-10, rtol=1e-14)

    def residual(m: float) -> float:
        x = m / (rho * 8e-5)
        rise = 40000.0 * (1.5 * speed ** 2 - 0.5 * x * abs(x))
        return rise - 1e6 * 0.005 * (m / 0.08) ** 2 - valve_dp(m) - rho * G * (1.5 - level)

    return brentq(residual, 1e-6, 0.2, xtol=1e-12, rtol=1e-14)


def test_heated_loop_hydraulics_level_and_heat_balance(fmu_cache) -> None:
    fmu = fmu_cache("TrackingBox.Fluid.Validation.HeatedLoop")
    names = ["tank.level", "tank.T", "tank.rho", "pump.m_flow", "pump.speed", "heater.Q_flow", "hex.Q_total",
             "tank.Q_loss", "heater.T", "hex.T2[1]"]
    with FMUModel(fmu, tolerance=1e-8) as model:
        df = model.simulate(stop_time=30000.0, output_interval=2.0, outputs=names)
    t = df["time"].to_numpy()
    # a closed loop of liquid-full parts: what leaves the tank comes back, the level stays at 0.8 m
    assert np.ptp(df["tank.level"].to_numpy()) < 1e-9
    # the flow is where the curves meet, at every speed of the 0.8-1.0 sine (checked at 25 instants;
    # the model writes pi as 3.14159, so does the speed here)
    for i in np.linspace(0, t.size - 1, 25).astype(int):
        row = df.iloc[i]
        speed = 0.9 + 0.1 * math.sin(2 * 3.14159 * row["time"] / 1000.0)
        assert row["pump.speed"] == pytest.approx(speed, abs=1e-12)
        m = _loop_flow(speed, row["tank.rho"], row["tank.level"])
        assert row["pump.m_flow"] == pytest.approx(m, rel=1e-6), row["time"]
    # the loop warms from 50 degC (the heater's 140 degC medium against the cold stream at 40 degC)
    assert df["tank.T"].iloc[-1] > 323.15 + 5.0
    # the Documentation's balance: once settled (30000 s is about 15 of the loop's thermal time
    # constants, its water over the exchangers' conductances), the heating unit's input over one
    # period of the speed equals the heat given to the cold stream plus the tank's loss. The heat
    # stored over that period is zero up to exp(-15); what remains is the balance's own error: each
    # volume's energy equation uses cp at its own temperature, and cp of water differs by 0.4 % between
    # the tank (64 degC) and the heating unit (89 degC), so heater input and heat out differ by about
    # m (cp_heater - cp_tank) dT = 0.083 kg/s * 16 J/(kg K) * 25 K = 33 W, 0.3-0.4 % of 8.2 kW
    # (measured: 0.29 %). 1 % allows for that and nothing of the size of the tank's loss (2.7 %).
    last = t >= 29000.0
    q_in = np.trapezoid(df["heater.Q_flow"].to_numpy()[last], t[last])
    q_out = np.trapezoid((df["hex.Q_total"] + df["tank.Q_loss"]).to_numpy()[last], t[last])
    assert q_in == pytest.approx(q_out, rel=1e-2), (q_in / 1000.0, q_out / 1000.0)
    # the cold stream leaves warmer than it came (40 degC) and colder than the loop
    assert 313.15 < df["hex.T2[1]"].iloc[-1] < df["heater.T"].iloc[-1]
