"""The evaporator's hidden-effect plants (``Benches.Evaporator.Hidden``) and ``bench evaporator --hidden``.

Each plant variant is ``Hidden.Clean`` plus one effect in its own functional form; each is
simulated for a few hours at the bench's nominal inputs (from the plant's own start) and
checked against what its documentation says, computed here by hand: the size of the
effect at the operating point (11 g/s of vent, 15 kW of shell loss, 5 g/s of carry-over),
the reading a mis-calibrated instrument gives (x*694/649; a level loop holding the
reading of a transmitter calibrated 8 % dense at its setpoint holds the true level 8 %
higher), the direction the effect moves a measured tag against ``Clean`` at the same
inputs, and for the air blanket the first-order fill and vent through a stoppage.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from trackingbox.benches import make_bench
from trackingbox.benches.evaporator import HIDDEN, NOMINAL
from trackingbox.errors import TrackingError

PKG = "TrackingBox.Benches.Evaporator.Hidden"
STOP = 3 * 3600.0
TAIL = STOP - 1800.0


def _run(fmu_cache, model: str, outputs: list[str], inputs: pd.DataFrame | None = None, stop: float = STOP):
    from trackingbox.fmu import FMUModel

    if inputs is None:
        inputs = pd.DataFrame({"time": [0.0, stop], **{k: [v, v] for k, v in NOMINAL.items()}})
    with FMUModel(fmu_cache(model)) as m:
        return m.simulate(stop_time=stop, output_interval=10.0, inputs=inputs, outputs=outputs)


@pytest.fixture(scope="module")
def clean(fmu_cache):
    return _run(fmu_cache, f"{PKG}.Clean", ["effect.x", "effect.T", "PI_flash", "TI_flash", "FI_product",
                                            "DI_product", "DS_product.port.x", "effect.m_vent", "effect.Q_loss",
                                            "flash.Q_loss", "Rf_scale", "effect.Rf_internal", "flash.level"])


def _tail(df: pd.DataFrame, name: str) -> float:
    return float(df[name][df["time"] >= TAIL].mean())


def test_cases_name_their_models_and_effects():
    from trackingbox.diagnose.library import load_effects

    effects = load_effects()
    assert HIDDEN["clean"].effect is None and HIDDEN["ncg-after-restart"].effect is None
    for case in HIDDEN.values():
        assert case.model.startswith(PKG + ".")
        assert case.effect is None or case.effect in effects, case.name


@pytest.mark.compile
def test_clean_hides_nothing(clean):
    """Clean: no vent, no loss, no scale, a true DS meter; the fouling 2e-4*(1 - exp(-t/1 d)) alone."""
    t = clean["time"].to_numpy()
    for name in ("effect.m_vent", "effect.Q_loss", "flash.Q_loss", "Rf_scale"):
        assert np.abs(clean[name]).max() == 0.0, name
    np.testing.assert_allclose(clean["DI_product"], clean["DS_product.port.x"], atol=1e-15)
    np.testing.assert_allclose(clean["effect.Rf_internal"], 2e-4 * (1 - np.exp(-t / 86400.0)), rtol=1e-9, atol=1e-15)
    # the operating point the cases are sized on: product at 74-81 % DS, the body near 131 degC
    assert 0.74 < _tail(clean, "effect.x") < 0.81
    assert 395.0 < _tail(clean, "effect.T") < 415.0


@pytest.mark.compile
def test_vent_orifice(fmu_cache):
    df = _run(fmu_cache, f"{PKG}.VentOrifice", ["effect.p_s", "effect.m_flow_vent_internal", "effect.m_steam",
                                                 "effect.m_c"])
    vent = _tail(df, "effect.m_flow_vent_internal")
    assert vent == pytest.approx(0.011 * math.sqrt((_tail(df, "effect.p_s") - 1e5) / 2.5e5), rel=0.01)
    assert 0.008 < vent < 0.014  # "about 11 g/s"
    assert 0.01 < vent / _tail(df, "effect.m_steam") < 0.025  # "1.5 % of the steam"
    # the chest is steady: what enters and is not condensed is the vent
    assert _tail(df, "effect.m_steam") - _tail(df, "effect.m_c") == pytest.approx(vent, rel=0.02)


@pytest.mark.compile
def test_shell_loss(fmu_cache, clean):
    df = _run(fmu_cache, f"{PKG}.ShellLoss", ["effect.T", "effect.Q_flow_loss_internal", "effect.x"])
    q = _tail(df, "effect.Q_flow_loss_internal")
    assert q == pytest.approx(45.0 * (_tail(df, "effect.T") - 298.15) ** 1.25, rel=0.01)
    assert 12e3 < q < 18e3  # "about 15 kW at 131 degC"
    # 15 kW less for evaporation: a thinner product than Clean's at the same inputs
    assert _tail(df, "effect.x") < _tail(clean, "effect.x") - 1e-3


@pytest.mark.compile
def test_flash_demister(fmu_cache, clean):
    df = _run(fmu_cache, f"{PKG}.FlashDemister", ["PI_flash", "flash.vapourCapacity_internal", "flash.m_vap_out"])
    base = _run(fmu_cache, f"{PKG}.Clean", ["PI_flash", "flash.m_vap_out"])
    capacity = _tail(df, "flash.vapourCapacity_internal")
    assert 0.3 < capacity < 0.6  # phi0 = 0.6 at no load, "about half" at the flash's flow
    # the flash vapour is what the liquor's drop to the tank's saturation releases: nearly the same, so the tank's
    # pressure rises until the clogged line passes it, by more than the 1/phi^(1...2) of its drop to the 1 bar
    # header that a linear (small drops, regularised) to square-root law needs
    dp, dp_clean = _tail(df, "PI_flash") - 1e5, _tail(base, "PI_flash") - 1e5
    flow, flow_clean = _tail(df, "flash.m_vap_out"), _tail(base, "flash.m_vap_out")
    assert flow / flow_clean == pytest.approx(1.0, abs=0.02)
    assert dp / dp_clean > 0.98 / capacity


@pytest.mark.compile
def test_borated_liquor(fmu_cache, clean):
    df = _run(fmu_cache, f"{PKG}.BoratedLiquor", ["effect.x", "effect.T_b", "effect.T_vap", "effect.BPR",
                                                   "effect.epsBPR", "TI_flash"])
    x = df["effect.x"].to_numpy()
    extra = df["effect.T_b"] - df["effect.T_vap"] - (1 + df["effect.epsBPR"]) * df["effect.BPR"]
    np.testing.assert_allclose(extra, 1.0 + 2.0 / (1 + np.exp(-(x - 0.72) / 0.02)), atol=1e-9)
    assert _tail(df, "TI_flash") > _tail(clean, "TI_flash") + 0.5  # the flash tank's liquor boils hotter


def _splus(z, eps):
    return 0.5 * (z + np.sqrt(z * z + eps * eps))


@pytest.mark.compile
def test_burkeite_scale(fmu_cache):
    """Thick liquor (low feed): the scale grows with the supersaturation by the documented law, and by taking
    duty away it brings the product back towards saturation (3 h: part of the way), where the clean plant runs
    above it."""
    feed = {**NOMINAL, "feedFlowSet": 1.3}
    inputs = pd.DataFrame({"time": [0.0, STOP], **{k: [v, v] for k, v in feed.items()}})
    df = _run(fmu_cache, f"{PKG}.BurkeiteScale", ["effect.x", "Rs", "effect.dRf_internal"], inputs)
    base = _run(fmu_cache, f"{PKG}.Clean", ["effect.x"], inputs)
    t = df["time"].to_numpy()
    x, rs = df["effect.x"].to_numpy(), df["Rs"].to_numpy()
    np.testing.assert_allclose(df["effect.dRf_internal"], rs, atol=1e-15)
    rate = 2e-6 * _splus(x - 0.795, 0.002) - _splus(0.795 - x, 0.002) / 0.01 * rs / 14400.0
    inner = slice(5, -5)
    np.testing.assert_allclose(np.gradient(rs, t)[inner], rate[inner], rtol=0.02, atol=1e-3 * np.abs(rate).max())
    assert rs[-1] > 5e-5
    assert _tail(base, "effect.x") > 0.805
    assert _tail(df, "effect.x") < _tail(base, "effect.x") - 0.002  # the scale took duty: thinner product


@pytest.mark.compile
def test_density_meter(fmu_cache):
    df = _run(fmu_cache, f"{PKG}.DensityMeter", ["DI_product", "DS_product.port.x"])
    np.testing.assert_allclose(df["DI_product"], df["DS_product.port.x"] * 694.0 / 649.0, rtol=1e-12)
    assert 0.035 < _tail(df, "DI_product") - _tail(df, "DS_product.port.x") < 0.06  # "5.3 %DS high at 77 %"


@pytest.mark.compile
def test_foaming_flash(fmu_cache, clean):
    df = _run(fmu_cache, f"{PKG}.FoamingFlash", ["flash.level", "LI_flash"])
    # the loop holds the reading at the 1.0 m setpoint; the true level is 1570/1450 of the reading
    assert _tail(df, "LI_flash") == pytest.approx(1.0, abs=0.01)
    # the same liquor (density) at the same reading: the true level is 1570/1450 of the clean plant's
    assert _tail(df, "flash.level") / _tail(clean, "flash.level") == pytest.approx(1570.0 / 1450.0, rel=0.002)


@pytest.mark.compile
def test_demister_carryover(fmu_cache, clean):
    df = _run(fmu_cache, f"{PKG}.DemisterCarryover", ["effect.m_ev", "effect.m_flow_entrain_internal", "FI_product"])
    np.testing.assert_allclose(df["effect.m_flow_entrain_internal"], 0.012 * df["effect.m_ev"] ** 2, rtol=1e-9)
    assert 0.003 < _tail(df, "effect.m_flow_entrain_internal") < 0.008  # "5 g/s"
    assert _tail(df, "FI_product") < _tail(clean, "FI_product")  # liquor lost with the vapour


@pytest.mark.compile
def test_ncg_after_restart(fmu_cache):
    """One stoppage of 1 h: the blanket fills to RBlanket with 600 s, then vents with 2400 s after the restart."""
    f0 = NOMINAL["feedFlowSet"]
    times = [0.0, 3600.0, 3630.0, 7230.0, 7260.0, 14400.0]
    inputs = pd.DataFrame({"time": times, "feedFlowSet": [f0, f0, 0.02, 0.02, f0, f0],
                           **{k: [v] * len(times) for k, v in NOMINAL.items() if k != "feedFlowSet"}})
    df = _run(fmu_cache, f"{PKG}.NcgAfterRestart", ["Rncg", "stopped", "inletValve.m_flow"], inputs, stop=14400.0)
    t = df["time"].to_numpy()
    r = df["Rncg"].to_numpy()
    assert r[t < 3600.0].max() < 1e-8  # running: no air
    at_restart = float(np.interp(7230.0, t, r))
    assert at_restart == pytest.approx(2.5e-4 * (1 - math.exp(-3500.0 / 600.0)), rel=0.05)
    # vented with 2400 s once the feed is back above 0.5 kg/s
    later = float(np.interp(7400.0 + 2400.0, t, r)) / float(np.interp(7400.0, t, r))
    assert later == pytest.approx(math.exp(-1.0), rel=0.05)


def test_unknown_case_is_named(tmp_path):
    with pytest.raises(TrackingError, match=r"unknown hidden-effect case 'vent-orifise'.*did you mean 'vent-orifice'"):
        make_bench("evaporator", tmp_path / "x", hidden="vent-orifise")
    assert not (tmp_path / "x").exists()
    with pytest.raises(TrackingError, match=r"unknown hidden-effect case 'vent-orifise' of bench 'evaporator-train'"
                                            r".*did you mean 'vent-orifice'"):
        make_bench("evaporator-train", tmp_path / "y", hidden="vent-orifise", effects=3)
    assert not (tmp_path / "y").exists()


@pytest.mark.compile
def test_bench_writes_a_hidden_case(fmu_cache, clean, tmp_path):
    """`bench evaporator --hidden density-meter`: the meter's error in the written data, the case in truth.json,
    the fouling declared varying for diagnose."""
    from trackingbox.spec import load_spec

    case = make_bench("evaporator", tmp_path / "dm", hours=2.0, hidden="density-meter",
                      plant_fmu=fmu_cache(f"{PKG}.DensityMeter"),
                      twin_fmu=fmu_cache("TrackingBox.Benches.Evaporator.Twin"))
    truth = json.loads(case.truth_file.read_text())
    assert truth["hidden"]["effect"] == "ds-meter" and truth["hidden"]["target"] == "DS_product"
    assert truth["plant_model"] == f"{PKG}.DensityMeter"
    assert load_spec(case.spec).diagnose.varying == (("effect.Rf", "rising"),)
    # after the 3 h warm-up at the nominal inputs (the scenario's first moves come later) the written
    # product DS reads 694/649 of what the plant holds there (0.3 %DS of noise, 0.2 %DS of dead band)
    long = pd.read_csv(case.measurements)
    qi = long[long["tag"] == "QI-6150"]["value"].astype(float)
    assert qi.median() == pytest.approx(_tail(clean, "DS_product.port.x") * 694.0 / 649.0, abs=0.01)
