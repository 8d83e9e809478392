"""Bench 1: counter-flow heat exchanger (``TrackingBox.Benches.HeatExchanger``).

Two water streams; the plant's heat-transfer coefficient ``hx.kht`` is 910
W/(m2.K) (fouled), the twin's 1000. Eight hours at 10 s sampling: steps and
ramps in both inlet flows and temperatures, plus slow drifts.
"""
from __future__ import annotations

import numpy as np

from ..spec import ParameterSpec, TrackingSettings
from . import scenario as sc
from .base import BenchDefinition, HiddenCase, Sensor

PACKAGE = "TrackingBox.Benches.HeatExchanger"

#: Plant input -> (initial value, lowest, highest, drift std, mean time between moves in s).
#: Nominal point of the model: hot 1 kg/s at 90 degC, cold 2 kg/s at 10 degC.
_INPUTS = {
    "mHot_flow": (1.0, 0.7, 1.3, 0.02, 4500.0),
    "mCold_flow": (2.0, 1.5, 2.5, 0.04, 5400.0),
    "ThIn": (363.15, 355.15, 368.15, 0.4, 6300.0),
    "TcIn": (283.15, 279.15, 288.15, 0.3, 9000.0),
}


def heat_exchanger_scenario(t: np.ndarray, rng: np.random.Generator, warmup: float) -> dict[str, np.ndarray]:
    """Inlet flows and temperatures: held through the warm-up, then moves and drifts.

    Each input starts at the nominal point; operating-point changes (steps and
    30 %-40 % of them ramps of 5-30 min) come at random about every 1.2-2.5 h, and a
    slow Ornstein-Uhlenbeck drift (correlation time 1 h) rides on top.
    """
    tm = np.maximum(t - warmup, 0.0)
    out: dict[str, np.ndarray] = {}
    for name, (base, low, high, spread, interval) in _INPUTS.items():
        y = sc.moves(tm, rng, base=base, low=low, high=high, mean_interval=interval, hold_start=900.0)
        y = y + sc.drift(tm, rng, sigma=spread, time_constant=3600.0)
        margin = 0.5 * (high - low)
        out[name] = np.clip(y, low - margin * 0.2, high + margin * 0.2)
    return out


_HIDDEN = f"{PACKAGE}.Hidden"

#: The hidden-effect suite of this bench (``trackingbox bench heat-exchanger --hidden NAME``).
HIDDEN = {c.name: c for c in (
    HiddenCase("fouling-exp", f"{_HIDDEN}.FoulingExp", "fouling", "hx",
               "hx.kht falls exponentially from the start of the data (25 % in the limit, time constant 4 h)",
               affected=("TI-102", "TI-202")),
    HiddenCase("heat-loss", f"{_HIDDEN}.HeatLoss", "heat-loss", "hx",
               "the hot side loses 40 W/K^1.25 * (T1[1] - 18 degC)^1.25 (about 6-8 kW) to the surroundings",
               affected=("TI-102", "TI-202")),
    HiddenCase("sensor-drift", f"{_HIDDEN}.SensorDrift", "sensor-drift", "TI-102",
               "TI-102 reads 1.5 K * (1 - exp(-t/20000 s)) too high", sensors={"TI-102": "ThOut_sensor"},
               affected=("TI-102",)),
    HiddenCase("sensor-lag", f"{_HIDDEN}.SensorLag", "sensor-lag", "TI-202",
               "TI-202 reads through two first-order lags in series (90 s and 30 s)",
               sensors={"TI-202": "TcOut_sensor"}, affected=("TI-202",)),
    HiddenCase("bypass", f"{_HIDDEN}.Bypass", None, None,
               "10 % of the hot flow bypasses the exchanger and joins before TI-102 (outside the library)",
               affected=("TI-102", "TI-202")),
)}

DEFINITION = BenchDefinition(
    name="heat-exchanger",
    title="Heat-exchanger bench (TrackingBox.Benches.HeatExchanger)",
    plant_model=f"{PACKAGE}.Plant",
    twin_model=f"{PACKAGE}.Twin",
    sample_time=10.0,
    hours=8.0,
    warmup=3600.0,
    inputs=(
        Sensor("FI-101", "mHot_flow", "mHot_flow", "flow"),
        Sensor("TI-100", "ThIn", "ThIn", "temperature"),
        Sensor("FI-201", "mCold_flow", "mCold_flow", "flow"),
        Sensor("TI-200", "TcIn", "TcIn", "temperature"),
    ),
    outputs=(
        Sensor("TI-102", "ThOut", "ThOut", "temperature"),
        Sensor("TI-202", "TcOut", "TcOut", "temperature"),
    ),
    # bounds as the model declares them (PartialBench: hx.kht(min=500, max=1500))
    parameters=(ParameterSpec("hx.kht", 1000.0, 500.0, 1500.0),),
    scenario=heat_exchanger_scenario,
    # the twin starts from its own initial temperatures: hold the controllers
    # until that start-up transient (residence times 1-2 min) has died out
    tracking=TrackingSettings(hold_until=600.0),
    hidden=HIDDEN,
)
