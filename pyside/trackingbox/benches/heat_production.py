"""Bench 2: heat-production process (``TrackingBox.Benches.HeatProduction``).

Preheating tank T100, storage tank T200, heating unit HU300, heat exchanger
HEX300 to an external cold stream, make-up tank T400. The plant has quadratic
pipe and pump curves and degraded components; the twin linear curves (pipe
loss proportional to the flow, pump curves the chord from shut-off to the
design point, as in the source) and the method notes' initial values. A day (24 h) at 10 s sampling of varying heat
demand (daily profile, noise, steps) and occasional setpoint changes.
"""
from __future__ import annotations

import numpy as np

from ..spec import ParameterSpec, StateSpec, TrackingSettings
from . import scenario as sc
from .base import BenchDefinition, HiddenCase, Sensor

PACKAGE = "TrackingBox.Benches.HeatProduction"


def heat_production_scenario(t: np.ndarray, rng: np.random.Generator, warmup: float) -> dict[str, np.ndarray]:
    """Heat demand and operating conditions over the day, held through the warm-up.

    * ``mCold_flow`` (heat demand): 0.045 kg/s at night to 0.085 kg/s at the morning
      peak (daily profile), +-0.008 kg/s demand steps every ~3 h, a 20-min
      correlated fluctuation of 0.002 kg/s; kept within 0.035..0.095 kg/s.
    * ``TColdIn``: 40 degC with a slow drift of 1 K (3 h correlation).
    * Setpoints ``TColdOut_set`` (65 degC), ``THU300_set`` (90 degC), ``TPre_set``
      (55 degC): operator steps of a few K about twice a day.
    * ``TMakeUp``: 15 degC with a slow drift of 0.5 K; ``TAmb``: 20 degC +- 5 K daily
      wave (warmest mid-afternoon) plus drift.
    """
    tm = np.maximum(t - warmup, 0.0)
    day = sc.daily_profile(tm, t0_hour=0.0)
    demand = 0.045 + 0.04 * day
    demand = demand + sc.moves(tm, rng, base=0.0, low=-0.008, high=0.008, mean_interval=3 * 3600.0,
                               ramp_fraction=0.3, hold_start=1800.0)
    demand = demand + sc.drift(tm, rng, sigma=0.002, time_constant=1200.0)
    out = {
        "mCold_flow": np.clip(demand, 0.035, 0.095),
        "TColdIn": 313.15 + sc.drift(tm, rng, sigma=1.0, time_constant=3 * 3600.0),
        "TColdOut_set": sc.moves(tm, rng, base=338.15, low=336.15, high=340.15, mean_interval=12 * 3600.0,
                                 ramp_fraction=0.0, hold_start=3600.0),
        "THU300_set": sc.moves(tm, rng, base=363.15, low=360.15, high=366.15, mean_interval=12 * 3600.0,
                               ramp_fraction=0.0, hold_start=3600.0),
        "TPre_set": sc.moves(tm, rng, base=328.15, low=326.15, high=330.15, mean_interval=16 * 3600.0,
                             ramp_fraction=0.0, hold_start=3600.0),
        "TMakeUp": 288.15 + sc.drift(tm, rng, sigma=0.5, time_constant=4 * 3600.0),
        "TAmb": (293.15 + 5.0 * np.sin(2 * np.pi * (tm - 9 * 3600.0) / 86400.0)
                 + sc.drift(tm, rng, sigma=0.7, time_constant=2 * 3600.0)),
    }
    return out


def _out(tag: str, variable: str, kind: str, **kw: object) -> Sensor:
    return Sensor(tag, variable, variable, kind, **kw)  # type: ignore[arg-type]


_HIDDEN = f"{PACKAGE}.Hidden"

#: The hidden-effect suite of this bench (``trackingbox bench heat-production --hidden NAME``).
HIDDEN = {c.name: c for c in (
    HiddenCase("leak-level", f"{_HIDDEN}.LeakLevel", "leak", "T200",
               "T200 leaks 0.0045 kg/s * sqrt(level / 1 m) (4 g/s at 0.8 m) from the start",
               affected=("FI-100", "SI-100")),
    HiddenCase("fouling-exp", f"{_HIDDEN}.FoulingExp", "fouling", "HEX300",
               "HEX300.kht falls exponentially from the start of the data (35 % in the limit, time constant 10 h)",
               affected=("TI-301", "FI-200", "SI-200")),
    HiddenCase("heat-loss", f"{_HIDDEN}.HeatLoss", "heat-loss", "T100",
               "T100 loses 8 W/K^1.25 * (T - TAmb)^1.25 (about 0.7 kW) more than designed, from the start",
               affected=("QI-100",)),
    HiddenCase("sensor-drift", f"{_HIDDEN}.SensorDrift", "sensor-drift", "TI-100",
               "TI-100 reads -2 K * (1 - exp(-t/50000 s)) off", sensors={"TI-100": "TI_100_sensor"},
               affected=("TI-100",)),
)}

DEFINITION = BenchDefinition(
    name="heat-production",
    title="Heat-production bench (TrackingBox.Benches.HeatProduction)",
    plant_model=f"{PACKAGE}.Plant",
    twin_model=f"{PACKAGE}.Twin",
    sample_time=10.0,
    hours=24.0,
    warmup=4 * 3600.0,
    inputs=(
        Sensor("FI-303", "mCold_flow", "mCold_flow", "flow"),
        Sensor("TI-303", "TColdIn", "TColdIn", "temperature"),
        Sensor("TIC-302.SP", "TColdOut_set", "TColdOut_set", "other"),
        Sensor("TIC-300.SP", "THU300_set", "THU300_set", "other"),
        Sensor("TIC-100.SP", "TPre_set", "TPre_set", "other"),
        Sensor("TI-401", "TMakeUp", "TMakeUp", "temperature"),
        Sensor("TI-001", "TAmb", "TAmb", "temperature"),
    ),
    outputs=(
        _out("LI-100", "LI_100", "level"),
        _out("LI-200", "LI_200", "level"),
        _out("LI-400", "LI_400", "level"),
        _out("TI-100", "TI_100", "temperature"),
        _out("TI-200", "TI_200", "temperature"),
        _out("TI-300", "TI_300", "temperature"),
        _out("TI-301", "TI_301", "temperature"),
        _out("TI-302", "TI_302", "temperature"),
        _out("TI-310", "TI_310", "temperature"),
        _out("TI-400", "TI_400", "temperature"),
        _out("FI-100", "FI_100", "flow"),
        _out("FI-101", "FI_101", "flow"),
        _out("FI-200", "FI_200", "flow"),
        _out("FI-400", "FI_400", "flow"),
        _out("PI-100", "PI_100", "pressure"),
        _out("PI-200", "PI_200", "pressure"),
        _out("PI-300", "PI_300", "pressure"),
        # controller outputs are known exactly in the DCS: no sensor noise
        _out("SI-100", "SI_100", "other"),
        _out("SI-200", "SI_200", "other"),
        _out("ZI-400", "ZI_400", "other"),
        _out("QI-100", "QI_100", "power"),
    ),
    # the method notes' table of initial values and bounds (as declared in the twin)
    parameters=(
        ParameterSpec("HU300.kht", 1050.0, 945.0, 1155.0),
        ParameterSpec("HEX300.kht", 1000.0, 850.0, 1150.0),
        ParameterSpec("Pipe100.k", 0.005, 0.0001, 0.01),
        ParameterSpec("Pipe101.k", 0.005, 0.0001, 0.01),
        ParameterSpec("Pipe200.k", 0.005, 0.0001, 0.01),
        ParameterSpec("Pipe201.k", 0.005, 0.0001, 0.01),
        ParameterSpec("V100.KvMax", 1.0, 0.9, 1.1),
        ParameterSpec("V200.KvMax", 1.0, 0.9, 1.1),
        ParameterSpec("V300.KvMax", 1.0, 0.9, 1.1),
        ParameterSpec("V400.KvMax", 1.0, 0.9, 1.1),
        ParameterSpec("PU100.VFlowDesign", 6.6e-5, 6.0e-5, 7.3e-5),
        ParameterSpec("PU100.uRise", 40000.0, 36000.0, 44000.0),
        ParameterSpec("PU200.VFlowDesign", 8.3e-5, 7.5e-5, 9.16e-5),
        ParameterSpec("PU200.uRise", 40000.0, 36000.0, 44000.0),
    ),
    scenario=heat_production_scenario,
    # state compensation of the tank levels through the twin's correction-flow inputs:
    # 1 kg/s per m on a 0.3 m2 tank (about 295 kg per m of level) closes a level gap
    # with a time constant of ~5 min and turns the 5 mm level noise into ~0.005 kg/s
    states=(
        StateSpec("LI-100", "LI_100", "T100_m_flow_corr", 1.0),
        StateSpec("LI-200", "LI_200", "T200_m_flow_corr", 1.0),
        StateSpec("LI-400", "LI_400", "T400_m_flow_corr", 1.0),
    ),
    # the twin starts from its declared initial state; its level and temperature
    # controllers (integral times 150-1200 s) need about an hour to settle
    tracking=TrackingSettings(hold_until=3600.0),
    hidden=HIDDEN,
    # the twin the hidden-effect suite diagnoses against: the source's linear curves leave a residual
    # of 10-30 noise standard deviations on most tags of the plain plant (an effect of its own, outside
    # the library: the plain bench against `Twin` is the suite's out-of-library case)
    suite_twin_model=f"{_HIDDEN}.QuadraticTwin",
)
