"""The three-parameter thermal case: a wall from ``Modelica.Thermal.HeatTransfer``, data with a known truth.

``modelica/Identify/ThermalWall.mo`` (shipped with the package) connects two
``PrescribedTemperature`` sources (the measured inside and outside air), two
``ThermalResistor`` (``R1``, ``R2``) and a ``HeatCapacitor`` (``C``) from the
Modelica Standard Library; a ``TemperatureSensor`` in the wall is the measured
output. Seen through the wall's temperature the model has the time constants
``R1·C`` and ``R2·C`` only: multiplying both resistances by a factor and
dividing the capacity by it changes nothing the sensor sees. The unmeasured
output ``Q_inside`` (the heat flow into the wall) would tell them apart.

:func:`compile_wall` builds its FMU with the MSL (embedded path);
:func:`wall_case` simulates it as the "plant" at :data:`TRUTH` with a day's
heating schedule and weather, adds sensor noise, and writes a spec whose
``[[parameters]]`` start off the truth -- the case the issue's user tried.
"""
from __future__ import annotations

import json
import math
import shutil
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..compiler import compile_model
from ..errors import TrackingError
from ..io import write_text_atomic
from ..simulation.models import open_model

#: The plant's true values.
TRUTH = {"R1": 0.02, "R2": 0.05, "C": 2.0e5}
#: The spec's start values and bounds (start values off the truth by factors 2, 0.6 and 0.5).
PARAMETERS = {"R1": (0.04, 0.005, 0.1), "R2": (0.03, 0.01, 0.25), "C": (1.0e5, 2.0e4, 1.0e6)}
#: Sensor noise standard deviations (K).
NOISE = {"TI-wall": 0.05, "TI-inside": 0.05, "TI-outside": 0.05}
MODEL = "ThermalWall"


def model_file() -> Path:
    """The shipped ``ThermalWall.mo``."""
    return Path(str(resources.files("trackingbox.modelica"))) / "Identify" / "ThermalWall.mo"


def compile_wall(output: str | Path, msl: str | Path) -> Path:
    """Compile ``ThermalWall`` against the Modelica Standard Library in *msl* (with ``Modelica`` and
    ``ModelicaServices`` in it) into the FMU *output*; returns its path."""
    msl = Path(msl)
    libraries = [msl / "Modelica", msl / "ModelicaServices"]
    missing = [str(p) for p in libraries if not p.is_dir()]
    if missing:
        raise TrackingError(f"the Modelica Standard Library is not where it was looked for: {', '.join(missing)}")
    result = compile_model(model_file(), MODEL, backend="embedded", output=output, libraries=libraries)
    return Path(result.fmu)


def weather(t: np.ndarray, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Inside air on a heating schedule (21 degC 6-22 h, 17 degC at night, with slow wander) and
    outside air (5 degC, a 6 K daily wave warmest at 15 h, an hour-scale drift), in K."""
    hour = (t / 3600.0) % 24.0
    inside = np.where((hour >= 6.0) & (hour < 22.0), 21.0, 17.0)
    inside = inside + _drift(t, rng, 0.4, 1800.0)
    outside = 5.0 + 6.0 * np.sin(2.0 * math.pi * (t / 3600.0 - 9.0) / 24.0) + _drift(t, rng, 1.5, 3 * 3600.0)
    return {"T_inside": 273.15 + inside, "T_outside": 273.15 + outside}


def _drift(t: np.ndarray, rng: np.random.Generator, sigma: float, tau: float) -> np.ndarray:
    """An Ornstein-Uhlenbeck wander of standard deviation *sigma* and correlation time *tau*."""
    out = np.zeros(t.size)
    for k in range(1, t.size):
        a = math.exp(-(t[k] - t[k - 1]) / tau)
        out[k] = a * out[k - 1] + sigma * math.sqrt(1.0 - a * a) * rng.standard_normal()
    return out


SPEC = """\
# thermal wall (trackingbox.identify.thermal): seed {seed}, truth in truth.json (not read by the spec)
twin = "twin.fmu"
measurements = "measurements.csv"
sample_time = {dt}

[inputs]
TI-inside = "T_inside"
TI-outside = "T_outside"

[outputs]
TI-wall = "T_wall"
{parameters}
[windows]
training = [0.0, {half}]
validation = [{half}, {end}]

[data]
initial = "steady"   # the plant starts settled at its first inputs: so does the twin
"""


def wall_case(out: str | Path, fmu: str | Path, *, seed: int = 0, hours: float = 48.0, dt: float = 60.0,
              truth: dict[str, float] | None = None, noise_scale: float = 1.0, known: tuple[str, ...] = ()) -> Path:
    """Write a thermal-wall case into *out* (``twin.fmu``, ``measurements.csv``, ``spec.toml``,
    ``truth.json``) from the compiled *fmu*; returns the spec's path.

    The plant starts settled at the first inputs (a 2-day held pre-run); so does the twin
    (``[data] initial = "steady"``: no run goes before the data's first sample, so no warm-up
    could settle it from its own start temperature). *known*: parameters
    held at their true values (``[fixed]``) instead of estimated (``("C",)``: R1 and R2
    alone, which the wall's temperature does determine).
    """
    truth = dict(TRUTH if truth is None else truth)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(np.random.SeedSequence(int(seed)).spawn(1)[0])
    t = np.arange(0.0, hours * 3600.0 + dt / 2, dt)
    u = weather(t, rng)
    pre = 2 * 86400.0
    frame = pd.DataFrame({"time": np.concatenate(([0.0], pre + t)),
                          **{k: np.concatenate(([v[0]], v)) for k, v in u.items()}})
    with open_model(fmu) as model:
        r = model.simulate(stop_time=pre + float(t[-1]), output_interval=dt, inputs=frame, parameters=truth,
                           outputs=["T_wall"])
    y = np.interp(pre + t, np.asarray(r["time"], dtype=float), np.asarray(r["T_wall"], dtype=float))
    data = {"time": t,
            "TI-inside": u["T_inside"] + noise_scale * NOISE["TI-inside"] * rng.standard_normal(t.size),
            "TI-outside": u["T_outside"] + noise_scale * NOISE["TI-outside"] * rng.standard_normal(t.size),
            "TI-wall": y + noise_scale * NOISE["TI-wall"] * rng.standard_normal(t.size)}
    pd.DataFrame(data).to_csv(out / "measurements.csv", index=False, float_format="%.9g")
    if Path(fmu).resolve() != (out / "twin.fmu").resolve():
        shutil.copyfile(fmu, out / "twin.fmu")
    unknown = [n for n in known if n not in PARAMETERS]
    if unknown:
        raise TrackingError(f"wall_case: known parameters must be among {', '.join(PARAMETERS)}, not {unknown}")
    params = "".join(f"\n[[parameters]]\nname = \"{n}\"\nstart = {s!r}\nmin = {lo!r}\nmax = {hi!r}\n"
                     for n, (s, lo, hi) in PARAMETERS.items() if n not in known)
    if known:
        params += "\n[fixed]\n" + "".join(f"{n} = {truth[n]!r}\n" for n in known)
    half = round(t.size / 2) * dt
    write_text_atomic(out / "spec.toml", SPEC.format(seed=seed, dt=dt, parameters=params, half=half, end=t[-1]))
    combos = {"R1·C": truth["R1"] * truth["C"], "R2·C": truth["R2"] * truth["C"]}
    write_text_atomic(out / "truth.json", json.dumps({"case": "thermal-wall", "seed": int(seed), "hours": hours,
                                                      "parameters": truth, "combinations": combos,
                                                      "noise": NOISE}, indent=2) + "\n")
    return out / "spec.toml"


def truth_of(directory: str | Path) -> dict[str, Any]:
    """The case's ``truth.json``."""
    return json.loads((Path(directory) / "truth.json").read_text(encoding="utf-8"))
