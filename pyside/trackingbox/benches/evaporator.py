"""Bench 3: the last effect of a black-liquor evaporation plant (``TrackingBox.Benches.Evaporator``).

The slice of the source thesis: liquor enters through a flow-controlled inlet
valve (setpoint ``feedFlowSet``), is concentrated in a falling-film effect heated
by steam at ``steamP``, leaves through a level-controlled outlet valve into a flash
tank and a pump; the steam chest's condensate goes to a condensate tank, the
vapour to the next effect at ``nextP``. The plant fouls (asymptotically, plus
scaling above ~50 % dry solids) and its valves and pump wear; the twin starts
clean. See ``../shared/docs/evaporator-notes.md``.

The scenario follows the notes' disturbances for the last effect (feed dry solids
50-55 %, feed temperature, steam pressure 3-4.5 bar(a), next-effect pressure) and
has several **flow stoppages** a day: the feed setpoint goes to ~0 within a
minute, stays there 10-60 min, and comes back. Measurements are written the way a
plant historian exports them (:mod:`trackingbox.benches.historian`: ISO 8601
timestamps, per-tag sampling, dead-band reporting, communication losses).

``truth.json`` holds, beside the constant plant values, the plant's fouling
resistance over time (``trajectories``) and the stoppage intervals, so the
tracked fouling parameter can be compared with what the plant really did.
"""
from __future__ import annotations

import json
import logging
import math
import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..errors import FMUError, SpecError, TrackingError, did_you_mean
from ..fmu import read_info
from ..io import atomic_path, write_text_atomic
from ..spec import (
    DataRules,
    DiagnoseSpec,
    PairingSettings,
    ParameterSpec,
    SourceSpec,
    Spec,
    StateSpec,
    StoppageRule,
    TrackingSettings,
    check_against_fmu,
    dump_spec,
    load_spec,
    loads_spec,
    write_pairs,
)
from . import scenario as sc
from .base import (
    BenchCase,
    BenchDefinition,
    HiddenCase,
    Sensor,
    _compile,
    _library_path,
    _tunable_parameters,
    check_overrides,
    noisy_measurements,
    simulate_plant,
)
from .historian import HistorianSettings, TagSettings, export_history

log = logging.getLogger(__name__)

PACKAGE = "TrackingBox.Benches.Evaporator"
FloatArray = npt.NDArray[np.float64]

# --------------------------------------------------------------------------- operating point

#: The slice's operating point (the notes' last effect on the liquor side, 1/10 scale; the
#: design point of ``Benches.Evaporator``): feed (kg/s), feed dry solids (1), feed
#: temperature (K), steam header pressure (Pa), next-effect vapour pressure (Pa).
NOMINAL: dict[str, float] = {
    "feedFlowSet": 2.0,
    "feedDS": 0.52,
    "feedT": 368.15,
    "steamP": 4.0e5,
    "nextP": 1.4e5,
}

#: Feed setpoint during a stoppage, as a fraction of the nominal feed ("to ~0").
STOPPED_FRACTION = 0.01


@dataclass(frozen=True)
class Stoppage:
    """One flow stoppage of the scenario (times in s from the first measured sample).

    The feed setpoint ramps from its value to ~0 over ``ramp_down`` s starting at
    ``start``, stays there until ``restart``, and ramps back over ``ramp_up`` s.
    """

    start: float
    restart: float
    ramp_down: float
    ramp_up: float

    @property
    def end(self) -> float:
        """When the feed is back at its running value."""
        return self.restart + self.ramp_up

    def to_json(self) -> dict[str, float]:
        return {"start": self.start, "restart": self.restart, "end": self.end,
                "ramp_down": self.ramp_down, "ramp_up": self.ramp_up}


def stoppage_schedule(duration: float, rng: np.random.Generator, *, per_day: tuple[int, int] = (2, 4),
                      first_after: float = 2 * 3600.0, hold: tuple[float, float] = (600.0, 3600.0),
                      ramp_down: tuple[float, float] = (20.0, 60.0),
                      ramp_up: tuple[float, float] = (120.0, 300.0)) -> list[Stoppage]:
    """Random flow stoppages over *duration* s: several a day, 10-60 min each.

    Each day gets between ``per_day[0]`` and ``per_day[1]`` stoppages, one in each
    of that many equal slots of the day (at a uniformly drawn time in the slot's
    first half, so they never overlap); the feed falls within *ramp_down* s (under a
    minute), is held off for a time drawn uniformly in *hold* and restarts over
    *ramp_up* s. Stoppages before *first_after* s or not over by *duration* are dropped.

    >>> s = stoppage_schedule(3 * 86400.0, np.random.default_rng(0))
    >>> len(s) >= 5 and all(600.0 <= x.restart - x.start - x.ramp_down <= 3600.0 for x in s)
    True
    """
    out: list[Stoppage] = []
    for day in range(int(math.ceil(duration / 86400.0))):
        n = int(rng.integers(per_day[0], per_day[1] + 1))
        slot = 86400.0 / n
        for i in range(n):
            when = day * 86400.0 + i * slot + rng.uniform(0.0, 0.5 * slot)
            down, held, up = rng.uniform(*ramp_down), rng.uniform(*hold), rng.uniform(*ramp_up)
            stop = Stoppage(start=float(when), restart=float(when + down + held), ramp_down=float(down),
                            ramp_up=float(up))
            if when >= first_after and stop.end < duration:
                out.append(stop)
    return out


def stoppage_factor(t: FloatArray, stoppages: Sequence[Stoppage], floor: float = STOPPED_FRACTION) -> FloatArray:
    """Multiplier of the feed setpoint: 1 running, *floor* stopped, linear ramps between.

    >>> stoppage_factor(np.array([0., 15., 30., 100., 110., 120.]), [Stoppage(10., 100., 10., 20.)], 0.0).tolist()
    [1.0, 0.5, 0.0, 0.0, 0.5, 1.0]
    """
    f = np.ones_like(t, dtype=float)
    for s in stoppages:
        down = np.clip((t - s.start) / s.ramp_down, 0.0, 1.0)
        up = np.clip((t - s.restart) / s.ramp_up, 0.0, 1.0)
        g = 1.0 - (1.0 - floor) * (down - up)
        f = np.minimum(f, g)
    return f


def evaporator_inputs(t: FloatArray, rng: np.random.Generator, warmup: float,
                      stoppages: Sequence[Stoppage], nominal: Mapping[str, float] = NOMINAL) -> dict[str, FloatArray]:
    """The plant's input trajectories on *t* (s, warm-up included), held through the warm-up.

    * ``feedFlowSet``: nominal feed with operator moves of +-10 % every ~6 h and a
      2 % drift, brought down to 1 % of the nominal feed in the stoppages
      (:func:`stoppage_factor`).
    * ``feedDS``: 52 % with moves in 50-55 % every ~8 h and a 0.4 %DS drift.
    * ``feedT``: nominal with a 1.5 K drift (3 h correlation).
    * ``steamP``: 4 bar(a) header with moves in 3.5-4.4 bar every ~12 h and a 0.05 bar
      drift (kept in 3.0-4.5 bar).
    * ``nextP``: nominal with a 3 kPa drift (2 h correlation).
    """
    tm = np.maximum(t - warmup, 0.0)
    f0 = nominal["feedFlowSet"]
    flow = sc.moves(tm, rng, base=f0, low=0.9 * f0, high=1.1 * f0, mean_interval=6 * 3600.0,
                    ramp_fraction=0.6, hold_start=2 * 3600.0)
    flow = flow * (1.0 + sc.drift(tm, rng, sigma=0.02, time_constant=1800.0))
    stopped = STOPPED_FRACTION * f0
    flow = stopped + (flow - stopped) * stoppage_factor(t - warmup, stoppages, 0.0)
    ds = sc.moves(tm, rng, base=nominal["feedDS"], low=0.50, high=0.55, mean_interval=8 * 3600.0,
                  ramp_fraction=0.8, ramp_duration=(1800.0, 5400.0), hold_start=3 * 3600.0)
    ds = np.clip(ds + sc.drift(tm, rng, sigma=0.004, time_constant=3600.0), 0.49, 0.56)
    steam = sc.moves(tm, rng, base=nominal["steamP"], low=3.5e5, high=4.4e5, mean_interval=12 * 3600.0,
                     ramp_fraction=0.7, ramp_duration=(600.0, 3600.0), hold_start=4 * 3600.0)
    steam = np.clip(steam + sc.drift(tm, rng, sigma=5e3, time_constant=1800.0), 3.0e5, 4.5e5)
    return {
        "feedFlowSet": flow,
        "feedDS": ds,
        "feedT": nominal["feedT"] + sc.drift(tm, rng, sigma=1.5, time_constant=3 * 3600.0),
        "steamP": steam,
        "nextP": nominal["nextP"] + sc.drift(tm, rng, sigma=3e3, time_constant=2 * 3600.0),
    }


def _scenario(t: FloatArray, rng: np.random.Generator, warmup: float) -> dict[str, FloatArray]:
    """:class:`BenchDefinition` form of the scenario (schedules its own stoppages)."""
    stoppages = stoppage_schedule(float(t[-1] - warmup), rng)
    return evaporator_inputs(t, rng, warmup, stoppages)


# --------------------------------------------------------------------------- tags


def _s(tag: str, variable: str, kind: str, sigma: float | None = None, relative: bool | None = None) -> Sensor:
    return Sensor(tag, variable, variable, kind, sigma=sigma, relative=relative)  # type: ignore[arg-type]


#: Sensor noise from the notes (section 5): flows 1 % of reading, pressures 0.2 kPa,
#: temperatures 0.2 K, levels 5 mm, dry solids 0.3 %DS; valve positions are DCS values.
INPUTS = (
    _s("FIC-6110.SP", "feedFlowSet", "other"),
    _s("QI-6100", "feedDS", "other", 0.003, False),
    _s("TI-6100", "feedT", "temperature", 0.2, False),
    _s("PI-6120", "steamP", "pressure", 200.0, False),
    _s("PI-6130", "nextP", "pressure", 200.0, False),
)
OUTPUTS = (
    _s("FI-6110", "FI_feed", "flow", 0.01, True),
    _s("FI-6150", "FI_product", "flow", 0.01, True),
    _s("FI-6125", "FI_condensate", "flow", 0.01, True),
    _s("PI-6111", "PI_vapour", "pressure", 200.0, False),
    _s("PI-6121", "PI_steamChest", "pressure", 200.0, False),
    _s("PI-6151", "PI_flash", "pressure", 200.0, False),
    _s("PI-6152", "PI_pump", "pressure", 200.0, False),
    _s("TI-6111", "TI_body", "temperature", 0.2, False),
    _s("TI-6151", "TI_flash", "temperature", 0.2, False),
    _s("LI-6111", "LI_body", "level", 0.005, False),
    _s("LI-6151", "LI_flash", "level", 0.005, False),
    _s("LI-6125", "LI_condensate", "level", 0.005, False),
    _s("QI-6150", "DI_product", "other", 0.003, False),
    _s("ZI-6110", "ZI_inlet", "other"),
    _s("ZI-6150", "ZI_outlet", "other"),
)

#: ``[pairing]`` of the spec (see ``trackingbox pair``): the step tests freeze **no** controller, as
#: ``track`` runs the twin (every loop active, the three levels held by state compensation), so each
#: gain is one the tracking loop will find. A capacity error then shows where the closed loop puts it
#: (notes section 4): the inlet valve's in the inlet valve position ZI-6110, the outlet valve's in the
#: effect level controller's output ZI-6150, and the pump's in its discharge pressure PI-6152, not in
#: the product flow: with the flash level loop active the product flow FI-6150 is what the mass balance
#: sends down, whatever the pump's head. Frozen flash and condensate loops (this spec's freeze before)
#: gave pump.dp0 a gain on FI-6150 that the tracked twin does not have: on the 3-day case (seed 0,
#: validation window) that pair left 0.51 of FI-6150's untracked NRMSE, and pump.dp0 ended at its bound.
#: Measured with this freeze (3-day case, seed 0, validation window, 3 h closed loops): pump.dp0 <->
#: PI-6152 0.035 of untracked (dp0 ends at 3.59e5 Pa, inside its bounds: the worn plant's 3.7e5 Pa with
#: its smaller VMax), inletValve.KvMax <-> ZI-6110 0.037 (ends at 15.51, the plant's 15.5), Rf <->
#: PI-6121 0.12. outletValve.KvMax <-> ZI-6150 is chosen (predicted 0.07) but reaches only 1.05: the
#: untracked ZI-6150 error is small (RMS 0.008, floor 0.001) because the plant's larger outlet valve and
#: its smaller outflow (fouling: less evaporation) cancel in it, and while the 3 h loop settles after Rf
#: starts moving (first 6 h of the window: mean error -0.013) its error exceeds that; from 48 h on the
#: 6 h means are within 0.002 and KvMax sits at 7.23 (plant 7.6). (That was without estimates.)
#: With the demo's order (estimate the constants first, effect.dBPR held at its estimate 0.941 K: see
#: ESTIMATE_ONLY) the fouling's unbiased tags are TI-6111 and QI-6150 (the Rf move each tag's training
#: offset implies: 1.9e-4 and 1.7e-4 m2.K/W, the plant's training mean 1.64e-4), not PI-6121 (5e-5: a
#: plant difference the twin lacks moves the steam chest's pressure too; which one is not measured). Hand-set Rf <-> TI-6111, pump.dp0 <->
#: PI-6152, outletValve.KvMax <-> ZI-6150 (3 h loops) met every criterion on the validation window:
#: tracked/untracked NRMSE 0.227, 0.155, 0.167; fouling within 6.2 % of its range after 12 h (4.8 % in
#: the stoppages, final 3.0 %), inside its bounds; the three levels inside their vessels. ``pair``
#: (floor-aware with this closed_loop; dBPR in [fixed]) now chooses exactly these three by itself, and
#: the same run gives the same figures; left out with reasons: inletValve.KvMax (ZI-6110 at its floor
#: once estimated: 89 %), pump.VMax (parallel to pump.dp0), the tags FI-6125, PI-6111, PI-6121, TI-6151,
#: ZI-6110 (noise floor 50, 62, 32, 31, 89 % of their settled untracked error), FI-6110 and PI-6151
#: (no candidate moves them), FI-6150 and QI-6150 (offsets out of reach).
#: Each tag is scaled by its sensor accuracy (the noise above; flows at their design reading, valve
#: positions at the historian's 0.2 % dead band) rather than by its measured range, which the feed and
#: steam moves set.
#: Closed-loop time constant (s) the evaporator's parameter controllers are tuned for: 3 h.
#: On the 3-day demo case (seed 0) the tracked fouling's largest error after 12 h fell from
#: 58 % of its bound range with lambda = 1 (tau_c = 70 min) to 40 % with 3 h: the noise of
#: the product DS reading no longer shows in it; the remaining bias is the plant's. The spec's
#: ``[pairing] closed_loop``: ``pair`` predicts each loop with it (what changes faster than 3 h,
#: the sensor noise and the historian's held values included, stays in the tracked error) and
#: tunes the new pairs for it.
CLOSED_LOOP = 3 * 3600.0

PAIRING = PairingSettings(
    freeze=(),
    closed_loop=CLOSED_LOOP,
    scale=(("FI-6110", 0.02), ("FI-6150", 0.013), ("FI-6125", 0.008), ("PI-6111", 200.0), ("PI-6121", 200.0),
           ("PI-6151", 200.0), ("PI-6152", 200.0), ("TI-6111", 0.2), ("TI-6151", 0.2), ("QI-6150", 0.003), ("ZI-6110", 0.002),
           ("ZI-6150", 0.002)),
)

#: Level tag -> (twin level output, twin correction-flow input, gain kg/s per m). The
#: vessels hold ~4350 (effect, 3 m2 at ~1450 kg/m3), ~2900 (flash tank) and ~950
#: (condensate tank) kg per m of level: the gains close a level gap in 8-25 min and
#: turn the 5 mm level noise into 0.01-0.03 kg/s of correction.
STATES = (
    StateSpec("LI-6111", "LI_body", "body_m_flow_corr", 6.0),
    StateSpec("LI-6151", "LI_flash", "flash_m_flow_corr", 2.0),
    StateSpec("LI-6125", "LI_condensate", "cond_m_flow_corr", 2.0),
)

#: Candidate tracking parameters: name -> (lower, upper) as fractions of the twin's
#: declared start value.
#: ``effect.U0`` is not one: its step-test column is parallel to ``effect.Rf``'s (the pairing
#: can only keep one of the two), and the Effect has no conditional input for it, so a pair on it
#: stops gen-trackingbox; the fouling resistance, with ``use_Rf_in``, is the tracked coefficient.
CANDIDATES: dict[str, tuple[float, float]] = {
    "inletValve.KvMax": (0.7, 1.3),
    "outletValve.KvMax": (0.7, 1.3),
    "pump.dp0": (0.7, 1.3),
    "pump.VMax": (0.7, 1.3),
}
RF_BOUNDS = (0.0, 6.0e-4)
#: Bounds of the twin's boiling-point offset (K): the notes give 0.5-2 K for the real liquor
#: against the correlation, and +5 K for borate above 70 % DS.
DBPR_BOUNDS = (-2.0, 5.0)
#: The twin's boiling-point offset ``effect.dBPR`` (K) as a tracked parameter: the notes' section 4
#: "delta BPR: TI liquor - Tsat(PI vapour), separates composition from fouling". Without it the
#: plant's 1 K offset (1 K of the effect's ~8 K driving difference) is read as fouling: a twin step
#: test at the design point shows 1 K of offset moving the condensate flow and the product DS as
#: much as 1.5e-4 m2.K/W of fouling (a quarter of the bound range), and on the 1-day case (seed 0,
#: Rf tracked on QI-6150, ``scripts/bench_evaporator_bias``) switching the plant's offset off moved
#: the tracked Rf's mean error after 6 h from +9.8e-5 to -4.2e-5 m2.K/W. With dBPR tracked on
#: TI-6111 and Rf on FI-6125 the same case's largest error after 6 h is 5.7 % of the range.
#: A candidate ``pair`` judges (:data:`ABSOLUTE`): on the 3-day case (seed 0, nothing frozen, second
#: operating point a running hour) its only tag, TI-6111, is left out by the tracking prediction (41 %
#: of its untracked error would remain, limit 25 %), and rightly: the untracked twin's TI-6111 error is
#: at the sensor's noise floor (training RMS 0.24 K, mean +0.06 K, against 0.2 K of sensor noise and the
#: historian's 0.2 K dead band), because the plant's +1 K offset and its lower product DS (fouling:
#: less evaporation, 0.46 K of BPR per %DS) cancel in it; no loop can bring a tag below its noise, so
#: the NRMSE criterion (<= 30 % of untracked) cannot hold there: its floor is 0.63 of the untracked RMS
#: on the validation window (``scripts/bench_evaporator_floor``). Tracked by hand (same case, 3 h loops:
#: Rf <-> FI-6125, dBPR <-> TI-6111, pump.dp0 <-> PI-6152, inletValve.KvMax <-> ZI-6110) TI-6111 reached
#: 0.645 (its floor), the others 0.20, 0.034, 0.037, dBPR ended at 0.87 K (plant 1.0 K) and the fouling's
#: largest error after 12 h was 4.3 % of its range (3.3 % in the stoppages, final 0.9 %); with Rf on
#: PI-6121 and dBPR left out (what ``pair`` chooses) it is 14.6 %.
DBPR = ParameterSpec("effect.dBPR", 0.0, *DBPR_BOUNDS)
#: Candidates with absolute (start, lower, upper): the contract's fouling resistance and the
#: boiling-point offset (:data:`DBPR`).
ABSOLUTE: dict[str, tuple[float, float, float]] = {
    "effect.Rf": (0.0, *RF_BOUNDS),
    DBPR.name: (DBPR.start, DBPR.min, DBPR.max),
}

#: Candidates that vary in time in any evaporator (fouling grows between cleanings): an estimate over
#: a window is their mean there, so the demo writes the other candidates' estimates as the spec's
#: starts before ``pair`` and leaves these at their clean start for the tracking loop to follow.
TIME_VARYING: tuple[str, ...] = ("effect.Rf",)

#: Candidates that are estimated, then held at their estimate (moved to ``[fixed]``) rather than
#: tracked: the boiling-point offset, a constant of the liquor's composition whose only tag, the
#: body temperature TI-6111, is also the fouling's best unbiased tag once the offset is right. Left a
#: candidate, ``pair`` gives TI-6111 to it (relative gain 0.58 against the fouling's 0.41) and the
#: fouling no tag (3-day case, seed 0).
ESTIMATE_ONLY: tuple[str, ...] = (DBPR.name,)


def fix_parameters(spec_path: str | os.PathLike[str], values: Mapping[str, float],
                   intervals: Mapping[str, tuple[float, float]] | None = None) -> Spec:
    """Move the ``[[parameters]]`` named in *values* into ``[fixed]`` at those values (atomically).

    *intervals*: the confidence intervals of those values (an estimate's), written as
    ``[fixed_intervals]``: the tracked parameters' bands carry what a held value may be off by.

    Raises
    ------
    SpecError
        A name that is not a ``[[parameters]]`` entry of the spec (named, with the file).
    """
    path = Path(spec_path)
    spec = load_spec(path)
    names = {p.name for p in spec.parameters}
    unknown = sorted(set(values) - names)
    if unknown:
        raise SpecError(f"{path}: {unknown} are not [[parameters]] entries; cannot fix them")
    fixed = {**spec.fixed, **{k: float(v) for k, v in values.items()}}
    held = {k: (float(a), float(b)) for k, (a, b) in (intervals or {}).items() if k in values}
    spec = replace(spec, parameters=tuple(p for p in spec.parameters if p.name not in values), fixed=fixed,
                   fixed_intervals={**{k: v for k, v in spec.fixed_intervals.items() if k not in values}, **held})
    text = dump_spec(spec)
    check = loads_spec(text, path, check_files=False)
    write_text_atomic(path, text)
    return check


#: Plant variables recorded in truth.json over time: twin parameter -> plant variable.
TRAJECTORIES: dict[str, str] = {"effect.Rf": "Rf_true"}

#: Feed flow below this fraction of nominal is a stoppage; the settle time after one.
STOPPAGE_BELOW = 0.3
STOPPAGE_SETTLE = 1800.0

_HIDDEN = f"{PACKAGE}.Hidden"

#: The hidden-effect suite of this bench (``trackingbox bench evaporator --hidden NAME``): the plant
#: ``Hidden.Clean`` (the bench plant with only what the twin describes: fouling, which it tracks, the
#: boiling-point offset and the wear, which it estimates) plus one effect, written in
#: ``Benches/Evaporator/Hidden`` independently of the diagnosis templates (other functional forms and
#: magnitudes, see its package documentation). ``clean`` hides nothing: diagnose must name nothing.
#: ``affected``: the tags whose noise-free reading moves by an RMS above 1.5 times the tag's accuracy
#: (``PAIRING.scale``) against the ``clean`` plant on the same inputs (``scripts/train_plant_diff CASE
#: CLEAN --stop 86400`` on ``bench evaporator --hidden CASE --hours 24 --seed 0``: the train's rule;
#: 2026-12-02). The flash tank's clogged vapour line moves no tag that far (PI-6151 0.41); the
#: carry-over moves PI-6152 alone, and only just (1.51); the air after each restart shows in the RMS only
#: (PI-6121 4.29, its mean 1.01).
HIDDEN = {c.name: c for c in (
    HiddenCase("clean", f"{_HIDDEN}.Clean", None, None,
               "nothing beyond the fouling the twin tracks (no vent, no heat loss, no scale, a true DS meter)"),
    HiddenCase("vent-orifice", f"{_HIDDEN}.VentOrifice", "steam-vent", "effect",
               "the steam chest vents 2.2e-5 kg/(s Pa^0.5) * sqrt(p_s - 1 bar) (about 11 g/s, 1.5 % of the steam)",
               affected=("PI-6121",)),
    HiddenCase("shell-loss", f"{_HIDDEN}.ShellLoss", "shell-heat-loss", "effect",
               "the effect's shell loses 45 W/K^1.25 * (T - 25 degC)^1.25 (about 15 kW at 131 degC)",
               affected=("PI-6121",)),
    HiddenCase("flash-demister", f"{_HIDDEN}.FlashDemister", "vapour-line", "flash",
               "the flash tank's vapour line passes 0.6/(1 + 4 s/kg * L) of its design law L",
               affected=()),
    HiddenCase("borated-liquor", f"{_HIDDEN}.BoratedLiquor", "bpr-offset", "effect",
               "the liquor boils 2 K * sigma((x - 0.72)/0.02) hotter in the effect and the flash tank (borate)",
               affected=("FI-6150", "FI-6125", "PI-6111", "PI-6121", "PI-6152", "TI-6111", "TI-6151", "QI-6150",
                         "ZI-6150"), also=("flash",)),
    HiddenCase("burkeite-scale", f"{_HIDDEN}.BurkeiteScale", "soluble-scale", "effect",
               "burkeite scale grows at 2e-6 m2.K/W per s per unit supersaturation above 79.5 % DS and "
               "dissolves below it",
               affected=("FI-6125", "PI-6121", "PI-6152", "TI-6111", "TI-6151", "QI-6150", "ZI-6150")),
    HiddenCase("density-meter", f"{_HIDDEN}.DensityMeter", "ds-meter", "DS_product",
               "the product DS meter reads x*694/649 (a density constant of 649 on a liquor of 694 kg/m3)",
               affected=("QI-6150",), instrument="QI-6150"),
    HiddenCase("foaming-flash", f"{_HIDDEN}.FoamingFlash", "level-density", "LT_flash",
               "the flash-tank level transmitter is calibrated for 1570 kg/m3 instead of 1450",
               affected=("PI-6152",)),
    HiddenCase("demister-carryover", f"{_HIDDEN}.DemisterCarryover", "entrainment", "effect",
               "the effect's vapour carries 0.012 s/kg * m_ev^2 of liquor (about 5 g/s)",
               affected=("PI-6152",)),
    HiddenCase("ncg-after-restart", f"{_HIDDEN}.NcgAfterRestart", None, None,
               "air blankets the steam chest in every stoppage (up to 2.5e-4 m2.K/W) and is vented with 40 min "
               "after the restart (outside the library)", affected=("PI-6121", "PI-6152")),
)}

#: ``[diagnose] varying`` of the spec: the fouling resistance is tracked in time (deposits build up
#: between cleanings), so diagnose's null model lets it rise as tracking would; a constant fouling
#: left its growth over the record (2e-4 m2.K/W) as a trend in PI-6152 that ``sensor-drift`` explained.
VARYING = (("effect.Rf", "rising"),)

DEFINITION = BenchDefinition(
    name="evaporator",
    title="Black-liquor evaporator, last effect (TrackingBox.Benches.Evaporator)",
    plant_model=f"{PACKAGE}.Plant",
    twin_model=f"{PACKAGE}.Twin",
    sample_time=10.0,
    hours=72.0,
    warmup=3 * 3600.0,
    inputs=INPUTS,
    outputs=OUTPUTS,
    parameters=(ParameterSpec("effect.Rf", 0.0, *RF_BOUNDS),),  # completed from the twin FMU in build()
    scenario=_scenario,
    states=STATES,
    # every tag is exception-reported with the same heartbeat: held between records, missing
    # after 1.5 heartbeats of silence or from a bad-quality event (the data layer's rule)
    data=DataRules(stoppage=StoppageRule("FI-6110", STOPPAGE_BELOW * NOMINAL["feedFlowSet"], STOPPAGE_SETTLE),
                   heartbeat={"*": 600.0}, initial="steady"),
    tracking=TrackingSettings(hold_until=3600.0),
    hidden=HIDDEN,
)


# --------------------------------------------------------------------------- build


def candidate_parameters(twin_info: Any) -> tuple[ParameterSpec, ...]:
    """The candidates: :data:`ABSOLUTE`, and :data:`CANDIDATES` around the twin FMU's declared starts
    (within its declared min/max).

    Raises
    ------
    FMUError
        A candidate the twin does not have (the contract's names are fixed).
    """
    params = _tunable_parameters(twin_info)
    missing = [n for n in (*ABSOLUTE, *CANDIDATES) if n not in params]
    if missing:
        raise FMUError(f"the evaporator twin ({PACKAGE}.Twin) lacks the tunable parameters {missing}")
    out = [ParameterSpec(name, *values) for name, values in ABSOLUTE.items()]
    for name, (lo, hi) in CANDIDATES.items():
        var = params[name]
        start = float(var.start)
        lower = max(lo * start, float(var.min)) if var.min is not None else lo * start
        upper = min(hi * start, float(var.max)) if var.max is not None else hi * start
        out.append(ParameterSpec(name, start, lower, upper))
    return tuple(out)


#: Heartbeat of every tag (s): the historian archives a steady tag at least this often.
HEARTBEAT = 600.0
#: The historian export's CSV form: ``long`` (``tag,time,value``, bad-quality events kept,
#: so the data layer never bridges a communication loss).
MEASUREMENT_FORM = "long"


def historian_settings(tags: Sequence[Sensor], start: str, seed: int, *, feed: float | None = None,
                       flow_band: float = 0.01, pressure_band: float = 300.0) -> Any:
    """Per-tag scan, dead band and heartbeat for :func:`~trackingbox.benches.historian.export_history`.

    Valve positions and setpoints are scanned every 2 s (dead band 0.2 % / 0.5 % of the
    nominal feed), flows and levels every 5 s (dead band 1 % / 5 mm), pressures and
    temperatures every 10 s (0.3 kPa / 0.2 K), the dry-solids analysers every 60 s
    (0.2 %DS); every tag has the heartbeat :data:`HEARTBEAT`. Two communication losses
    a day on average (5-45 min), half of them taking every tag.

    Parameters
    ----------
    tags : sequence of Sensor
        The tags exported.
    start : str
        ISO 8601 time of the first sample.
    seed : int
        Seed of the scan jitter and the communication losses.
    feed : float, optional
        Nominal feed (kg/s) the flow and setpoint dead bands are fractions of; default
        this bench's ``NOMINAL["feedFlowSet"]``.
    flow_band : float
        Flows' dead band as a fraction of *feed* (default 1 %).
    pressure_band : float
        Pressures' dead band (Pa; default 300 Pa).
    """
    f0 = NOMINAL["feedFlowSet"] if feed is None else float(feed)
    out = {}
    for s in tags:
        if s.tag.endswith(".SP"):
            scan, band = 2.0, 0.005 * f0
        elif s.tag.startswith("ZI"):
            scan, band = 2.0, 0.002
        elif s.kind == "flow":
            scan, band = 5.0, flow_band * f0
        elif s.kind == "level":
            scan, band = 5.0, 0.005
        elif s.kind == "pressure":
            scan, band = 10.0, pressure_band
        elif s.kind == "temperature":
            scan, band = 10.0, 0.2
        else:  # dry-solids analysers
            scan, band = 60.0, 0.002
        out[s.tag] = TagSettings(scan=scan, jitter=0.2, deadband=band, heartbeat=HEARTBEAT)
    return HistorianSettings(tags=out, start=start, seed=int(seed))


def _hidden_case(hidden: str | None, noise_scale: float) -> tuple[BenchDefinition, HiddenCase | None]:
    """The bench with the plant of hidden-effect case *hidden* (:data:`HIDDEN`), and the case; checks *noise_scale*."""
    if not (math.isfinite(noise_scale) and noise_scale >= 0):
        raise TrackingError(f"bench 'evaporator': the noise scale must be a number >= 0, got {noise_scale!r}")
    if hidden is None:
        return DEFINITION, None
    if hidden not in HIDDEN:
        raise TrackingError(f"unknown hidden-effect case {hidden!r} of bench 'evaporator'"
                            f"{did_you_mean(hidden, list(HIDDEN))}; choose one of {', '.join(HIDDEN)}")
    return replace(DEFINITION, plant_model=HIDDEN[hidden].model), HIDDEN[hidden]


def build(out: str | os.PathLike[str], *, seed: int = 0, overrides: Mapping[str, float] | None = None,
          hours: float | None = None, plant_fmu: str | os.PathLike[str] | None = None,
          twin_fmu: str | os.PathLike[str] | None = None, start: str = "2026-01-12T06:00:00+00:00",
          historian_export: bool = True, stoppages: Sequence[Stoppage] | None = None,
          hidden: str | None = None, noise_scale: float = 1.0) -> BenchCase:
    """Generate the evaporator case into *out* (the files of :func:`trackingbox.benches.make_bench`).

    Differs from the generic :func:`~trackingbox.benches.base.build_case` in three ways:
    the candidates' starts and bounds come from the twin FMU, ``measurements.csv`` is a
    historian export (ISO 8601 timestamps from *start*, per-tag sampling, dead band,
    communication losses) unless *historian_export* is False, and ``truth.json`` also
    holds the plant's fouling over time and the stoppages.

    Parameters
    ----------
    out : path-like
    seed : int
    overrides : mapping, optional
        Plant parameter values (e.g. ``RfInf``, ``tauFouling``).
    hours : float, optional
        Measured period (default 72 h: 3 days).
    plant_fmu, twin_fmu : path-like, optional
        Compiled FMUs to reuse.
    start : str
        ISO 8601 time of the first measured sample.
    historian_export : bool
        False writes the dense noisy samples (time in s) instead.
    stoppages : sequence of Stoppage, optional
        The flow stoppages (s from the first measured sample); default: drawn by
        :func:`stoppage_schedule` from the seed.
    hidden : str, optional
        A hidden-effect case (:data:`HIDDEN`): its plant variant is simulated instead of
        ``Plant``; ``truth.json`` says what is hidden.
    noise_scale : float
        Factor on every sensor's noise.

    Returns
    -------
    BenchCase
    """
    d, case_hidden = _hidden_case(hidden, noise_scale)
    out = Path(out).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise TrackingError(f"output directory {out} of bench 'evaporator' exists and is not a directory")
    hours = float(d.hours if hours is None else hours)
    if not hours > 0:
        raise TrackingError(f"bench 'evaporator': the measured period must be > 0 h, got {hours:g}")
    for given, what in ((plant_fmu, "plant"), (twin_fmu, "twin")):
        if given is not None and not Path(given).is_file():
            raise FMUError(f"{what} FMU {given} for bench 'evaporator' does not exist")
    scenario_rng, noise_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(2))

    with tempfile.TemporaryDirectory(prefix="bench-evaporator-") as tmpdir:
        stage = Path(tmpdir)
        staged = {"plant": stage / "plant.fmu", "twin": stage / "twin.fmu"}
        for what, given, model in (("plant", plant_fmu, d.plant_model), ("twin", twin_fmu, d.twin_model)):
            src = Path(given) if given is not None else _compile(model, stage / "build" / f"{what}.fmu")
            shutil.copyfile(src, staged[what])
        plant_info = read_info(staged["plant"])
        twin_info = read_info(staged["twin"])
        overrides = check_overrides(dict(overrides or {}), plant_info, f"the evaporator plant ({d.plant_model})")
        parameters = candidate_parameters(twin_info)

        # scenario over warm-up + measured period
        dt, warmup = d.sample_time, d.warmup
        n_meas, n_warm = int(round(hours * 3600.0 / dt)), int(round(warmup / dt))
        t_all = np.arange(n_warm + n_meas + 1) * dt
        drawn = stoppage_schedule(hours * 3600.0, scenario_rng)
        stoppages = drawn if stoppages is None else list(stoppages)
        true_inputs = evaporator_inputs(t_all, scenario_rng, warmup, stoppages)
        frame = pd.DataFrame({"time": t_all, **true_inputs})

        # plant simulation: the sensors' variables and the recorded truth
        names = {v.name for v in plant_info.variables}
        recorded = {tw: pv for tw, pv in TRAJECTORIES.items() if pv in names}
        plant_vars = list(dict.fromkeys([s.plant for s in d.outputs] + list(recorded.values())))
        log.info("simulating the evaporator plant for %.1f h (+%.1f h warm-up)", hours, warmup / 3600)
        result, plant_seconds, _ = simulate_plant(staged["plant"], t_all, frame, overrides, plant_vars, d.name)

        # measurements: true signals on the measured period + sensor noise, then the historian
        keep = slice(n_warm, None)
        t_meas = t_all[keep] - warmup
        dense_frame = noisy_measurements(t_meas, d.inputs, d.outputs, true_inputs, result, keep, noise_scale, noise_rng)
        history = None
        if historian_export:
            history = export_history(dense_frame, historian_settings((*d.inputs, *d.outputs), start, seed))
        plant_inputs = frame.iloc[keep].copy()
        plant_inputs["time"] = t_meas

        # truth: constants, trajectories (every minute), stoppages
        plant_params = {n: float(v.start) for n, v in _tunable_parameters(plant_info).items() if v.start is not None}
        plant_params.update(overrides)
        truth = {p.name: plant_params[p.name] for p in parameters if p.name in plant_params}
        every = max(1, int(round(60.0 / dt)))
        trajectories = {tw: {"time": t_meas[::every].tolist(), "value": result[pv].to_numpy(float)[keep][::every].tolist()}
                        for tw, pv in recorded.items()}
        truth_doc = {"bench": d.name, "seed": int(seed), "hours": hours, "start": str(pd.Timestamp(start)),
                     "plant_model": d.plant_model, "twin_model": d.twin_model, "overrides": overrides,
                     "parameters": truth, "plant_parameters": plant_params, "trajectories": trajectories,
                     "stoppages": [s.to_json() for s in stoppages],
                     "historian": history.to_json() if history is not None else None,
                     "plant_simulation_seconds": plant_seconds, "noise_scale": float(noise_scale),
                     "hidden": case_hidden.to_json() if case_hidden is not None else None}

        # spec
        lib = _library_path()
        half, end = round(n_meas / 2) * dt, n_meas * dt
        data = d.data if history is not None else DataRules(stoppage=d.data.stoppage, initial=d.data.initial)
        spec = Spec(
            path=out / "spec.toml", twin=out / "twin.fmu", measurements=out / "measurements.csv",
            sample_time=dt,
            source=SourceSpec(path=lib, model=d.twin_model) if lib is not None else None,
            inputs={s.tag: s.twin for s in d.inputs},
            outputs={s.tag: s.twin for s in d.outputs if s.tag not in {st.tag for st in d.states}},
            parameters=parameters, windows={"training": (0.0, half), "validation": (half, end)},
            data=data, states=d.states, tracking=d.tracking, pairing=PAIRING,
            diagnose=DiagnoseSpec(varying=VARYING),
        )
        command = "trackingbox bench evaporator" + (f" --hidden {hidden}" if hidden else "")
        header = (f"{d.title}: generated by `{command}`\n"
                  f"seed = {seed}, hours = {hours:g}, noise scale = {noise_scale:g}, plant overrides = "
                  f"{json.dumps(overrides) if overrides else 'none'}\n"
                  f"measurements as a historian exports them; the plant's fouling over time is in truth.json")
        spec_text = dump_spec(spec, header=header)
        check_against_fmu(loads_spec(spec_text, out / "spec.toml", check_files=False), twin_info)

        # publish: FMUs first, spec last
        out.mkdir(parents=True, exist_ok=True)
        for what, name in ((staged["plant"], "plant.fmu"), (staged["twin"], "twin.fmu")):
            with atomic_path(out / name) as tmp:
                shutil.copyfile(what, tmp)
        if history is not None:
            history.write(out / "measurements.csv", MEASUREMENT_FORM)
        else:
            with atomic_path(out / "measurements.csv") as tmp:
                dense_frame.to_csv(tmp, index=False, float_format="%.9g")
        with atomic_path(out / "plant_inputs.csv") as tmp:
            plant_inputs.to_csv(tmp, index=False, float_format="%.9g")
        write_text_atomic(out / "truth.json", json.dumps(truth_doc, indent=2, sort_keys=True) + "\n")
        write_text_atomic(out / "spec.toml", spec_text)

    load_spec(out / "spec.toml")
    log.info("wrote bench case evaporator to %s", out)
    return BenchCase(name=d.name, directory=out, spec=out / "spec.toml", twin_fmu=out / "twin.fmu",
                     plant_fmu=out / "plant.fmu", measurements=out / "measurements.csv",
                     plant_inputs=out / "plant_inputs.csv", truth_file=out / "truth.json", truth=truth,
                     plant_parameters=plant_params, seed=int(seed), hours=hours)


# --------------------------------------------------------------------------- tuning

def slow_pairs(spec_path: str | os.PathLike[str], closed_loop: float = CLOSED_LOOP) -> Spec:
    """Set each pair's ``lambda`` so that its closed-loop time constant is at least *closed_loop* s.

    The heat-transfer coefficient moves the condensate flow within seconds and then
    creeps back over an hour (the steam chest settles): the step test's time constant
    is a few seconds, shorter than the 10 s sample time, and SIMC tuning on it gives a
    per-sample loop gain near 1.4 on the final gain, over 2 on the first jump: the
    parameter then flips between its bounds every sample. Fouling, wear and scale
    change over hours to days, so a closed loop of hours loses little and keeps the
    measurement noise out of the parameter. Pairs that already have a larger
    ``lambda`` (or explicit ``kp``/``ti``) keep them.
    """
    spec = load_spec(spec_path)
    pairs = [p if (p.kp is not None or p.ti is not None or p.lambda_ * p.time_constant >= closed_loop)
             else replace(p, lambda_=closed_loop / p.time_constant) for p in spec.pairs]
    return write_pairs(spec_path, pairs)


# --------------------------------------------------------------------------- truth helpers


def load_truth(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read an evaporator case's ``truth.json``."""
    return json.loads(Path(path).read_text())


def truth_on(truth: Mapping[str, Any], name: str, t: npt.ArrayLike) -> FloatArray | None:
    """The plant's true value of parameter *name* at times *t* (s), from its trajectory or its constant."""
    t = np.asarray(t, dtype=float)
    traj = truth.get("trajectories", {}).get(name)
    if traj is not None:
        return np.interp(t, np.asarray(traj["time"], float), np.asarray(traj["value"], float))
    value = truth.get("parameters", {}).get(name)
    return None if value is None else np.full(t.shape, float(value))


def stoppage_intervals(truth: Mapping[str, Any]) -> list[tuple[float, float]]:
    """(start, end) of each stoppage in s, from ``truth.json``."""
    return [(float(s["start"]), float(s["end"])) for s in truth.get("stoppages", [])]
