"""Evaporator bench models (Plant, Twin): the steady operating point against the
design figures of the evaporator notes and hand energy balances, and a one-hour
feed stoppage that neither drains nor floods a vessel.

References: the notes' design figures (last effect: liquor in 50-55 % DS, out
75-80 %, steam 3-4.5 bar(a), BPR about 20 K at 77-80 % DS), the notes'
boiling-point-rise correlation and specific heat re-typed here, water/steam
from IAPWS-IF97 (``iapws``).
"""
from __future__ import annotations

import numpy as np
import pytest
from iapws import IAPWS97

from trackingbox.fmu import FMUModel

pytestmark = pytest.mark.compile

MODELS = ["TrackingBox.Benches.Evaporator.Plant", "TrackingBox.Benches.Evaporator.Twin"]
FEED_DS, FEED_T = 0.52, 368.15  # the inputs' start values (PartialSlice)
#: vessel heights above the level's zero (Effect, FlashTank, CondensateTank defaults)
HEIGHTS = {"effect": 3.0, "flash": 3.0, "condTank": 2.0}
#: plant-only boiling-point offset (Plant.dBPR)
DBPR = {"Plant": 1.0, "Twin": 0.0}


def tsat(p: float) -> float:
    return IAPWS97(P=p / 1e6, x=0).T


def hfg(T: float) -> float:
    return 1000 * (IAPWS97(T=T, x=1).h - IAPWS97(T=T, x=0).h)


def bpr(x: float, p: float) -> float:
    """Boiling-point rise, K (evaporator notes, section 1)."""
    atm = 6.173 * x - 7.48 * x**1.5 + 32.747 * x**2
    return atm * (1 + 0.6 * (tsat(p) - 373.16) / 100)


def cp_liquor(x: float, T: float) -> float:
    t = T - 273.15
    return 1000 * (4.216 * (1 - x) + (1.675 + 3.31 * t / 1000) * x + (4.87 - 20 * t / 1000) * (1 - x) * x**3)


TAGS = ["FI_feed", "FI_product", "FI_condensate", "FI_steam", "PI_vapour", "PI_flash", "PI_steamChest",
        "TI_body", "TI_flash", "LI_body", "LI_flash", "LI_condensate", "DI_product", "ZI_inlet", "ZI_outlet"]


@pytest.fixture(scope="module", params=MODELS, ids=["Plant", "Twin"])
def steady(request, fmu_cache):
    """(variant, last sample) after 8 h at the design boundaries (the inputs' start values)."""
    with FMUModel(fmu_cache(request.param), tolerance=1e-8) as m:
        df = m.simulate(stop_time=8 * 3600, output_interval=600, outputs=TAGS + ["effect.x", "effect.m_out"])
    return request.param.rsplit(".", 1)[1], df.iloc[-1]


def test_design_point(steady):
    variant, s = steady
    assert s["FI_feed"] == pytest.approx(2.0, rel=1e-3)  # the flow loop holds its setpoint
    assert 0.75 <= s["DI_product"] <= 0.80  # last effect: out 75-80 % DS
    assert 3e5 <= s["PI_steamChest"] <= 4.5e5  # steam 3-4.5 bar(a)
    assert 0.5 <= s["ZI_inlet"] <= 0.8 and 0.3 <= s["ZI_outlet"] <= 0.7  # valves in their working range
    for level, setpoint in (("LI_body", 1.2), ("LI_flash", 1.0), ("LI_condensate", 0.8)):
        assert s[level] == pytest.approx(setpoint, abs=2e-3)


def test_dry_solids_balance_at_steady_state(steady):
    variant, s = steady
    if variant == "Plant":  # the plant's DS meter has a bias and a drift
        return
    assert s["FI_product"] * s["DI_product"] == pytest.approx(s["FI_feed"] * FEED_DS, rel=1e-5)


def test_boiling_point_rise_at_the_body(steady):
    variant, s = steady
    x = s["effect.x"]
    rise = s["TI_body"] - tsat(s["PI_vapour"])
    # relaxation offset m_ev/K_ev (about 0.13 K) on top of the boiling point
    assert rise == pytest.approx(bpr(x, s["PI_vapour"]) + DBPR[variant], abs=0.3)
    assert 18 < rise < 24  # the notes' table: 21.9 K at 80 % DS and 146 kPa


def test_evaporation_against_steam_by_energy_balance(steady):
    variant, s = steady
    q = s["FI_condensate"] * hfg(tsat(s["PI_steamChest"]))
    body = (q - s["FI_feed"] * cp_liquor(FEED_DS, 0.5 * (FEED_T + s["TI_body"])) * (s["TI_body"] - FEED_T)) / hfg(
        tsat(s["PI_vapour"]))
    flash = s["effect.m_out"] * cp_liquor(s["effect.x"], s["TI_body"]) * (s["TI_body"] - s["TI_flash"]) / hfg(
        tsat(s["PI_flash"]))
    evaporated = s["FI_feed"] - s["FI_product"]
    assert evaporated == pytest.approx(body + flash, rel=0.06)
    # steam economy of one effect: a little below 1
    assert 0.75 < evaporated / s["FI_steam"] < 1.0


STOP = ["TrackingBox.Benches.Evaporator.Validation.PlantStoppage", "TrackingBox.Benches.Evaporator.Validation.TwinStoppage"]


@pytest.fixture(scope="module", params=STOP, ids=["Plant", "Twin"])
def stoppage(request, fmu_cache):
    cols = [f"bench.{t}" for t in TAGS] + [f"bench.{v}.level" for v in HEIGHTS]
    with FMUModel(fmu_cache(request.param)) as m:
        df = m.simulate(stop_time=14400, output_interval=10, outputs=cols)
    return df.rename(columns=lambda c: c.removeprefix("bench."))


def test_stoppage_shuts_feed_and_steam(stoppage):
    df = stoppage
    during = df[(df.time > 4000) & (df.time < 7200)]
    assert during["FI_feed"].max() < 0.03
    assert during["FI_steam"].max() < 0.05 * df[df.time < 3600]["FI_steam"].iloc[-1]
    after = df[df.time > 13000]
    assert after["FI_feed"].min() == pytest.approx(2.0, rel=5e-3)


def test_levels_stay_in_their_vessels(stoppage):
    df = stoppage
    for vessel, height in HEIGHTS.items():
        level = df[f"{vessel}.level"]
        assert level.min() > 0.1 * height, vessel
        assert level.max() < 0.9 * height, vessel
    end = df.iloc[-1]
    for tag, setpoint in (("LI_body", 1.2), ("LI_flash", 1.0), ("LI_condensate", 0.8)):
        assert end[tag] == pytest.approx(setpoint, abs=0.05), tag


def test_temperatures_do_not_jump(stoppage):
    df = stoppage[stoppage.time >= 1800]  # after the start-up from the start values
    before = df[df.time < 3600].iloc[-1]
    for tag in ("TI_body", "TI_flash"):
        steps = np.abs(np.diff(df[tag].to_numpy()))
        assert steps.max() < 0.2, tag  # K per 10 s
        assert (df[tag] - before[tag]).abs().max() < 3.0, tag


def test_hold_freezes_every_controller(fmu_cache):
    """holdControllers > 0.5 holds the valve positions (step tests with frozen loops), and releasing it is bumpless."""
    import pandas as pd

    inputs = pd.DataFrame({"time": [0.0, 3600.0, 3601.0, 5400.0, 5401.0, 9000.0],
                           "holdControllers": [0.0, 0.0, 1.0, 1.0, 0.0, 0.0],
                           "feedFlowSet": [2.0, 2.0, 2.0, 2.0, 2.0, 2.0]})
    # a feed-DS step while held moves levels and flows, not the valves
    inputs["feedDS"] = [0.52, 0.52, 0.54, 0.54, 0.54, 0.54]
    zi = ["ZI_inlet", "ZI_outlet", "ZI_product", "ZI_condensate"]
    with FMUModel(fmu_cache("TrackingBox.Benches.Evaporator.Twin")) as m:
        df = m.simulate(stop_time=9000, output_interval=10, inputs=inputs, outputs=zi + ["LI_body", "DI_product"])
    held = df[(df.time >= 3700) & (df.time <= 5400)]
    for tag in zi:
        assert np.ptp(held[tag]) < 1e-4, tag
    assert np.ptp(held["DI_product"]) > 1e-3  # the process did move
    released = df[df.time >= 5400]
    for tag in zi:  # no jump on release: at most 0.01 per 10 s
        assert np.abs(np.diff(released[tag].to_numpy())).max() < 0.01, tag
