"""Media functions (``TrackingBox.Media.Water.Saturation``, ``TrackingBox.Media.BlackLiquor``)
against independent references, evaluated through the compiled FMU of
``TrackingBox.Media.Validation.Properties`` (one compile per session).

References:
- water and steam: IAPWS-IF97 as implemented by the ``iapws`` package, over 20..200 degC;
  the evaporator notes' fits are within 0.38 % (p), 0.06 K (T), 4.7 kJ/kg (hfg),
  6 kJ/kg (h liquid), 4 kJ/kg (h vapour); ours are held to much tighter bounds;
- black liquor: the values tabulated in ``docs/evaporator-notes.md`` section 1 (rounded
  to the digits printed there) and hand-computed values of the published formulas.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from iapws import IAPWS97

from trackingbox.fmu import FMUModel

pytestmark = pytest.mark.compile

MODEL = "TrackingBox.Media.Validation.Properties"
P_ATM = 101325.0
T_GRID = np.linspace(293.15, 473.15, 181)  # 20..200 degC, 1 K apart


@pytest.fixture(scope="module")
def media(fmu_cache):
    """``media(T=..., p=..., x=...)`` → DataFrame of every output at those points (broadcast)."""
    model = FMUModel(fmu_cache(MODEL))

    def evaluate(T=373.15, p=P_ATM, x=0.5) -> pd.DataFrame:
        T, p, x = np.broadcast_arrays(np.atleast_1d(np.asarray(T, float)),
                                      np.atleast_1d(np.asarray(p, float)),
                                      np.atleast_1d(np.asarray(x, float)))
        n = T.size
        # one input sample per second; the outputs are read exactly at the sample times
        inputs = pd.DataFrame({"time": np.arange(n, dtype=float), "T": T, "p": p, "x": x})
        if n == 1:
            inputs = pd.concat([inputs, inputs.assign(time=1.0)], ignore_index=True)
        out = model.simulate(stop_time=max(n - 1, 1), output_interval=1.0, inputs=inputs)
        return out.iloc[:n].reset_index(drop=True)

    yield evaluate
    model.close()


@pytest.fixture(scope="module")
def iapws_sat():
    """IAPWS-IF97 saturation states on ``T_GRID``: pressure (Pa), liquid and vapour enthalpy (J/kg)."""
    liquid = [IAPWS97(T=float(t), x=0) for t in T_GRID]
    vapour = [IAPWS97(T=float(t), x=1) for t in T_GRID]
    return {
        "p": np.array([s.P * 1e6 for s in liquid]),
        "hf": np.array([s.h * 1e3 for s in liquid]),
        "hg": np.array([s.h * 1e3 for s in vapour]),
    }


# -- water and steam ----------------------------------------------------------------

def test_saturation_pressure_matches_iapws_if97(media, iapws_sat):
    out = media(T=T_GRID)
    rel = np.abs(out["pSat"] / iapws_sat["p"] - 1)
    assert rel.max() < 1e-7  # the notes' Antoine fit: 3.8e-3


def test_saturation_temperature_matches_iapws_if97(media, iapws_sat):
    out = media(T=T_GRID, p=iapws_sat["p"])
    assert np.abs(out["TSat"] - T_GRID).max() < 1e-5  # K; the notes' fit: 0.06 K
    # pSat and TSat are inverse to each other
    assert np.abs(out["TSatOfpSat"] - T_GRID).max() < 1e-5
    # a familiar point: the normal boiling point of water is 99.97 degC on ITS-90
    assert media(p=P_ATM)["TSat"][0] == pytest.approx(373.124, abs=1e-3)


def test_saturated_enthalpies_match_iapws_if97(media, iapws_sat):
    out = media(T=T_GRID)
    assert np.abs(out["hLiquid"] - iapws_sat["hf"]).max() < 10.0  # J/kg; the notes' fit: 6 kJ/kg
    assert np.abs(out["hVapour"] - iapws_sat["hg"]).max() < 20.0  # the notes' fit: 4 kJ/kg
    assert np.abs(out["hfg"] - (iapws_sat["hg"] - iapws_sat["hf"])).max() < 30.0  # notes: 4.7 kJ/kg


def test_saturation_functions_between_grid_points(media):
    """Off the 1 K grid (the fits were made on a 0.25 K grid): still within the same bounds."""
    T = np.array([293.4, 310.77, 351.123, 399.99, 431.5, 472.9])
    out = media(T=T)
    ref = [(IAPWS97(T=float(t), x=0), IAPWS97(T=float(t), x=1)) for t in T]
    assert np.abs(out["pSat"] / np.array([f.P * 1e6 for f, _ in ref]) - 1).max() < 1e-7
    assert np.abs(out["hLiquid"] - np.array([f.h * 1e3 for f, _ in ref])).max() < 10.0
    assert np.abs(out["hVapour"] - np.array([g.h * 1e3 for _, g in ref])).max() < 20.0


# -- black liquor --------------------------------------------------------------------

# the notes' table: boiling-point rise (K) at 101 kPa
BPR_TABLE = [(0.15, 1.2), (0.30, 3.6), (0.50, 8.6), (0.65, 13.9), (0.80, 20.5)]


def test_boiling_point_rise_matches_the_notes_table(media):
    xs = np.array([x for x, _ in BPR_TABLE])
    out = media(x=xs, p=P_ATM)
    for (x, expected), got in zip(BPR_TABLE, out["bpr"]):
        assert got == pytest.approx(expected, abs=0.05), f"x = {x}"  # printed to 0.1 K


@pytest.mark.parametrize(("p", "factor"), [(15e3, 0.72), (300e3, 1.20)])
def test_boiling_point_rise_pressure_factor(media, p, factor):
    xs = np.array([x for x, _ in BPR_TABLE])
    at_p = media(x=xs, p=p)["bpr"].to_numpy()
    at_atm = media(x=xs, p=P_ATM)["bpr"].to_numpy()
    assert np.allclose(at_p / at_atm, factor, atol=0.005)  # printed to 0.01


def test_boiling_point_rise_slope_at_75_percent(media):
    d = 1e-3
    out = media(x=[0.75 - d, 0.75 + d], p=P_ATM)["bpr"].to_numpy()
    slope = (out[1] - out[0]) / (2 * d)
    assert slope == pytest.approx(46.0, abs=0.5)  # "about 46 K per unit x, 1 %DS = 0.46 K"
    # hand derivative of the formula: 6.173 - 1.5*7.48*sqrt(0.75) + 2*32.747*0.75 (times the
    # pressure factor at 101325 Pa, 1 + 0.6*(373.124 - 373.16)/100)
    hand = (6.173 - 1.5 * 7.48 * np.sqrt(0.75) + 2 * 32.747 * 0.75) * (1 + 0.6 * (373.1243 - 373.16) / 100)
    assert slope == pytest.approx(hand, rel=1e-5)


def test_boiling_point_rise_vanishes_for_water_and_is_finite_below_zero(media):
    out = media(x=[0.0, -1e-3], p=P_ATM)["bpr"].to_numpy()
    assert abs(out[0]) < 1e-3
    assert np.isfinite(out[1]) and abs(out[1]) < 0.01


@pytest.mark.parametrize(("x", "t", "cp"), [(0.15, 60.0, 3.88), (0.5, 100.0, 3.29), (0.8, 130.0, 2.76)])
def test_liquor_heat_capacity_matches_the_notes(media, x, t, cp):
    got = media(x=x, T=273.15 + t)["cpLiquor"][0]
    assert got / 1000 == pytest.approx(cp, abs=0.005)  # printed to 0.01 kJ/(kg.K)


def test_liquor_heat_capacity_of_water_limit(media):
    # x = 0: the formula's water term alone, 4.216 kJ/(kg.K) at every temperature
    out = media(x=0.0, T=[293.15, 373.15, 423.15])
    assert np.allclose(out["cpLiquor"], 4216.0, rtol=1e-12)


def test_liquor_density_k649_vs_k694(media):
    # the notes' 1484 vs 1518 kg/m3 at x = 0.75 are (997 + k x) alone, i.e. where the
    # temperature factor 1.008 - 0.237e-3 t - 1.94e-6 t^2 equals 1: t = 27.5 degC
    a, b, c = 1.94e-6, 0.237e-3, -0.008
    t_ref = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    assert t_ref == pytest.approx(27.54, abs=0.01)
    out = media(x=0.75, T=273.15 + t_ref)
    assert out["rhoLiquor"][0] == pytest.approx(997 + 649 * 0.75, abs=1e-6)  # 1483.75
    assert out["rhoLiquor694"][0] == pytest.approx(997 + 694 * 0.75, abs=1e-6)  # 1517.5
    assert abs(out["rhoLiquor"][0] - 1484) <= 0.5 + 1e-9 and abs(out["rhoLiquor694"][0] - 1518) <= 0.5 + 1e-9
    # a hand-computed point at 100 degC, x = 0.5: (997 + 324.5)(1.008 - 0.0237 - 0.0194)
    assert media(x=0.5, T=373.15)["rhoLiquor"][0] == pytest.approx(1321.5 * 0.9649, rel=1e-12)


def test_density_with_the_wrong_k_misreads_dry_solids_by_about_5_percent(media):
    """The notes' hidden effect: a density measured on k = 694 liquor read back with k = 649."""
    rho = media(x=0.75, T=373.15)["rhoLiquor694"][0]
    factor = 1.008 - 0.237e-3 * 100 - 1.94e-6 * 100**2
    x_read = (rho / factor - 997) / 649
    assert x_read - 0.75 == pytest.approx(0.052, abs=0.002)


def test_liquor_enthalpy_is_the_integral_of_cp(media):
    xs = np.array([0.0, 0.15, 0.5, 0.65, 0.8])
    # zero at 0 degC for every x
    assert np.abs(media(x=xs, T=273.15)["hLiquor"]).max() < 1e-9
    # dh/dT = cp by central differences (exact for h quadratic in T, up to rounding)
    for T in (313.15, 373.15, 423.15):
        d = 0.05
        lo, hi = media(x=xs, T=T - d)["hLiquor"], media(x=xs, T=T + d)["hLiquor"]
        cp = media(x=xs, T=T)["cpLiquor"]
        assert np.allclose((hi - lo) / (2 * d), cp, rtol=1e-7), f"T = {T}"
    # and a hand value: x = 0.5, 100 degC:
    # a = 4.216*0.5 + 1.675*0.5 + 4.87*0.5*0.125 = 3.249875 kJ/(kg.K)
    # b = 3.31e-3*0.5 - 0.020*0.5*0.125 = 4.05e-4 kJ/(kg.K2); h = a*100 + b*100^2/2
    assert media(x=0.5, T=373.15)["hLiquor"][0] == pytest.approx(1000 * (324.9875 + 2.025), rel=1e-12)


# -- smoothness -----------------------------------------------------------------------

MEDIA = Path(__file__).resolve().parents[1] / "modelica" / "TrackingBox" / "Media"
# constructs that make events (or discontinuities) in Modelica
EVENTFUL = re.compile(r"\b(if|when|max|min|abs|sign|floor|ceil|integer|div|mod|rem|pre|edge|sample|reinit)\b\s*\(?")


@pytest.mark.parametrize("path", sorted(p for sub in ("Water/Saturation", "BlackLiquor")
                                         for p in (MEDIA / sub).glob("*.mo")), ids=lambda p: p.name)
def test_media_functions_are_event_free(path):
    code = re.sub(r"annotation\s*\(.*", "", path.read_text(), flags=re.S)  # documentation aside
    code = re.sub(r'"[^"]*"', '""', code)  # description strings aside
    hits = [m.group(0) for m in EVENTFUL.finditer(code)]
    assert not hits, f"{path.name} uses {hits}"


def test_media_functions_are_smooth_across_the_range(media):
    """No kinks: a kink shows as an isolated spike of the second difference, i.e. a fourth
    difference as large as the second; on a smooth curve the fourth is tiny in comparison."""
    T = np.linspace(293.15, 473.15, 721)
    out = media(T=T, p=media(T=T)["pSat"].to_numpy(), x=np.linspace(0.05, 0.85, 721))  # x^1.5: no curvature bound at 0
    for name in ("pSat", "TSat", "hLiquid", "hVapour", "hfg", "bpr", "cpLiquor", "hLiquor", "rhoLiquor"):
        y = out[name].to_numpy()
        d2, d4 = np.diff(y, 2), np.diff(y, 4)
        assert np.abs(d4).max() < 0.01 * np.abs(d2).max() + 1e-12 * np.abs(y).max(), name
