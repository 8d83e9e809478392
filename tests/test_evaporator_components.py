"""Evaporation components: the balances of a slice run close, and steady states
agree with hand calculations.

References are independent of the model's code: the conservation laws
(boundary integrals against inventories), water/steam from IAPWS-IF97 (the
``iapws`` package), the black-liquor correlations of the evaporator notes
re-typed here in Python, the Kv definition, the pump curve and the hand
relations of the notes (flash fraction, evaporation = heat / latent heat).
"""
from __future__ import annotations

import numpy as np
import pytest
from iapws import IAPWS97

from trackingbox.fmu import FMUModel

pytestmark = pytest.mark.compile

BALANCE = "TrackingBox.Evaporation.Validation.SliceBalance"
TWIN = "TrackingBox.Benches.Evaporator.Twin"


# -- independent references ---------------------------------------------------
def cp_liquor(x: float, T: float) -> float:
    """Specific heat of black liquor, J/(kg.K) (evaporator notes, section 1)."""
    t = T - 273.15
    return 1000 * (4.216 * (1 - x) + (1.675 + 3.31 * t / 1000) * x + (4.87 - 20 * t / 1000) * (1 - x) * x**3)


def h_liquor(x: float, T: float) -> float:
    """Specific enthalpy of black liquor, J/kg: the integral of ``cp_liquor`` from 0 degC."""
    t = T - 273.15
    return 1000 * (4.216 * (1 - x) * t + (1.675 * t + 3.31e-3 * t**2 / 2) * x + (4.87 * t - 0.01 * t**2) * (1 - x) * x**3)


def h_vapour(T: float) -> float:
    """Specific enthalpy of saturated steam at T, J/kg (IAPWS-IF97; liquid at 0.01 degC = 0)."""
    return 1000 * IAPWS97(T=T, x=1).h


def rho_liquor(x: float, T: float, k: float = 649.0) -> float:
    """Density of black liquor, kg/m3 (evaporator notes, section 1)."""
    t = (T - 273.15) / 1000
    return (997 + k * x) * (1.008 - 0.237 * t - 1.94 * t**2)


def hfg(T: float) -> float:
    """Latent heat of water at T, J/kg (IAPWS-IF97)."""
    return 1000 * (IAPWS97(T=T, x=1).h - IAPWS97(T=T, x=0).h)


def tsat(p: float) -> float:
    """Saturation temperature of water at p (Pa), K (IAPWS-IF97)."""
    return IAPWS97(P=p / 1e6, x=0).T


# -- fixtures -------------------------------------------------------------------
@pytest.fixture(scope="module")
def balance_run(fmu_cache):
    cols = ["massIn", "massOut", "solidsIn", "solidsOut", "energyIn", "energyOut",
            "massInventory", "solidsInventory", "energyInventory", "slice.FI_feed"]
    with FMUModel(fmu_cache(BALANCE), tolerance=1e-8) as m:
        return m.simulate(stop_time=7200, output_interval=60, outputs=cols)


STEADY = [
    "flash.m_in", "flash.m_ev", "flash.port_a.x", "flash.port_a.T", "flash.x", "flash.T", "flash.T_b", "flash.T_vap",
    "effect.m_in", "effect.m_ev", "effect.Q", "effect.T", "effect.x", "effect.T_vap", "effect.T_s", "effect.m_c",
    "effect.port_a.T", "effect.port_a.x", "effect.rho",
    "inletValve.m_flow", "inletValve.opening", "inletValve.port_a.p", "inletValve.port_b.p",
    "inletValve.port_a.x", "inletValve.port_a.T",
    "pump.m_flow", "pump.port_a.p", "pump.port_b.p", "pump.port_a.x", "pump.port_a.T",
    "effect.level", "LI_body",
]


@pytest.fixture(scope="module")
def twin_steady(fmu_cache):
    """The twin after 8 h at constant design boundaries (its start values)."""
    with FMUModel(fmu_cache(TWIN), tolerance=1e-8) as m:
        df = m.simulate(stop_time=8 * 3600, output_interval=600, outputs=STEADY)
    last, before = df.iloc[-1], df.iloc[-2]
    # steady: nothing moves by more than 1e-4 relative over the last 10 min
    moving = [n for n in STEADY if abs(last[n] - before[n]) > 1e-4 * max(abs(last[n]), 1e-3)]
    assert not moving, f"not steady after 8 h: {moving}"
    return last


# -- balances -------------------------------------------------------------------
@pytest.mark.parametrize("quantity", ["mass", "solids", "energy"])
def test_slice_balances_close(balance_run, quantity):
    df = balance_run
    change = df[f"{quantity}Inventory"].iloc[-1] - df[f"{quantity}Inventory"].iloc[0]
    net = df[f"{quantity}In"].iloc[-1] - df[f"{quantity}Out"].iloc[-1]
    throughput = df[f"{quantity}In"].iloc[-1]
    assert throughput > 0 and abs(change) > 1e-3 * throughput  # the run does move the inventories
    assert abs(change - net) <= 1e-6 * throughput, (quantity, change, net, throughput)


def test_balance_run_has_a_feed_change(balance_run):
    feed = balance_run["slice.FI_feed"].to_numpy()
    assert feed[:20].mean() == pytest.approx(2.0, rel=0.02)
    assert feed[-20:].mean() == pytest.approx(1.2, rel=0.02)


# -- steady states against hand calculations --------------------------------------------
def test_flash_fraction_and_dry_solids(twin_steady):
    s = twin_steady
    phi = s["flash.m_ev"] / s["flash.m_in"]
    x_in, T_in = s["flash.port_a.x"], s["flash.port_a.T"]
    # mass and solids at steady state: x_out = x_in/(1 - phi)
    assert s["flash.x"] == pytest.approx(x_in / (1 - phi), rel=1e-6)
    # the notes' estimate phi = cp (T_in - T_bf)/h_fg (liquid enthalpy of the
    # vapour neglected, cp at the inlet): a few per cent
    phi_hand = cp_liquor(x_in, T_in) * (T_in - s["flash.T_b"]) / hfg(s["flash.T_vap"])
    assert 0.005 < phi < 0.05
    assert phi == pytest.approx(phi_hand, rel=0.12)
    # the same with the vapour's enthalpy counted from the liquor it leaves
    # (h_g(T_vap) - h(x_out, T_out), which the notes' h_fg approximates): within 0.5 %
    phi_exact = (h_liquor(x_in, T_in) - h_liquor(s["flash.x"], s["flash.T"])) / (
        h_vapour(s["flash.T_vap"]) - h_liquor(s["flash.x"], s["flash.T"]))
    assert phi == pytest.approx(phi_exact, rel=5e-3)


def test_effect_evaporation_is_heat_over_latent_heat(twin_steady):
    s = twin_steady
    # heat left after warming the feed to the body temperature, over the latent heat
    x_mean = 0.5 * (s["effect.port_a.x"] + s["effect.x"])
    T_mean = 0.5 * (s["effect.port_a.T"] + s["effect.T"])
    sensible = s["effect.m_in"] * cp_liquor(x_mean, T_mean) * (s["effect.T"] - s["effect.port_a.T"])
    m_ev_hand = (s["effect.Q"] - sensible) / hfg(s["effect.T_vap"])
    assert s["effect.m_ev"] == pytest.approx(m_ev_hand, rel=0.05)
    # with the vapour counted from the liquor it leaves and the exact enthalpy change of the feed: within 0.5 %
    h_body = h_liquor(s["effect.x"], s["effect.T"])
    m_ev_exact = (s["effect.Q"] - s["effect.m_in"] * (h_body - h_liquor(s["effect.port_a.x"], s["effect.port_a.T"]))) / (
        h_vapour(s["effect.T_vap"]) - h_body)
    assert s["effect.m_ev"] == pytest.approx(m_ev_exact, rel=5e-3)
    # the chest condenses Q/h_fg(T_s)
    assert s["effect.m_c"] == pytest.approx(s["effect.Q"] / hfg(s["effect.T_s"]), rel=0.01)


def test_inlet_valve_follows_the_kv_law(twin_steady):
    s = twin_steady
    kv_max, R, leak = 17.0, 30.0, 1e-3  # PartialSlice: inletValve(KvMax=17, equalPercentage=true)
    y = s["inletValve.opening"]
    f = (R**y - 1) / (R - 1)
    kv = kv_max * (leak + (1 - leak) * f)
    rho = rho_liquor(s["inletValve.port_a.x"], s["inletValve.port_a.T"])
    dp = s["inletValve.port_a.p"] - s["inletValve.port_b.p"]
    # Kv: m3/h of a liquid of specific gravity rho/1000 at 1 bar
    m_flow = rho * kv * np.sqrt(dp / 1e5 / (rho / 1000)) / 3600
    assert s["inletValve.m_flow"] == pytest.approx(m_flow, rel=1e-4)


def test_pump_follows_its_curve(twin_steady):
    s = twin_steady
    dp0, vmax = 4e5, 3e-3  # PartialSlice: pump(dp0=4e5, VMax=3e-3)
    V = s["pump.m_flow"] / rho_liquor(s["pump.port_a.x"], s["pump.port_a.T"])
    assert s["pump.port_b.p"] - s["pump.port_a.p"] == pytest.approx(dp0 * (1 - (V / vmax) ** 2), rel=1e-6)


def test_level_transmitter_uses_the_calibration_density(twin_steady):
    s = twin_steady
    rho_true = rho_liquor(s["effect.x"], s["effect.T"])
    assert s["effect.rho"] == pytest.approx(rho_true, rel=1e-9)
    # dP = rho g L, read with rho_cal = 1450 kg/m3
    assert s["LI_body"] == pytest.approx(s["effect.level"] * rho_true / 1450, rel=1e-6)
