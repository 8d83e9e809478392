"""Own-model cases (issue 30): a model written elsewhere, a plant variant of it, and the plant's historian data.

Each :class:`OwnCase` is what a user brings to trackingbox: the twin's Modelica source, built on the
Modelica Standard Library (a package of the user's, or one of the MSL's own examples left unchanged),
and a historian export of the plant's tags. The plant is a variant of the twin made here, with one
parameter that degrades over the run (fouling, a wet insulation) and noisy sensors; its Modelica text
is written from the twin's own (:func:`plant_package`), so the plant and the twin share everything
but the degradation. :func:`write_historian` compiles the plant on the embedded path, simulates it over
the case's scenario and writes ``historian.csv`` (ISO 8601 times, one column per tag) and
``truth.json`` (the degrading parameter's trajectory). Where the twin and its data go from there is
``docs/your-own-model.md``'s and ``scripts/bench_own_model``'s business.
"""
from __future__ import annotations

import json
import math
import re
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from ..compiler import compile_model
from ..fmu import FMUModel
from ..generate.variants import _class_text, library_index  # the twin's text, read as gen-trackingbox reads it

__all__ = ["OwnCase", "CASES", "repository_root", "default_msl", "plant_package", "write_historian", "write_spec",
           "example_folder"]


def repository_root() -> Path:
    """The repository this package is installed from (editable install)."""
    return Path(__file__).resolve().parents[3]


def default_msl() -> Path:
    """The Modelica Standard Library 4.0.0 beside the repository (``../shared/msl/Modelica``)."""
    return repository_root().parent / "shared" / "msl" / "Modelica"


def example_folder() -> Path:
    """The tutorial's example folder (``examples/own-model``: the RCWall package and its historian)."""
    return repository_root() / "examples" / "own-model"


@dataclass(frozen=True)
class OwnCase:
    """One own-model case.

    Attributes
    ----------
    name, title
        Short name (``--case``) and a line saying what it is.
    twin_path, twin_model
        The twin's source as the spec names it (``"MSL"``: the MSL's ``Modelica`` directory) and class.
    plant_edit
        ``(declaration in the twin's text, what the plant declares instead, equations the plant adds)``:
        how the plant variant differs from the twin (the declaration matched whatever the white space).
    truth
        The degrading twin parameter and its value as a function of time (s from the first sample).
    inputs
        Tag -> (twin input, scenario function of time).
    outputs
        Tag -> (twin variable, sensor noise standard deviation).
    parameters
        ``(name, start, min, max)`` of the candidates the spec lists.
    fixed
        Known parameter values (``[fixed]``).
    sample_time, hours, training_hours
        The historian's sampling (s), its length and the training window's length (h); the
        validation window is the rest.
    initial
        The spec's ``[data] initial``.
    """

    name: str
    title: str
    twin_path: str
    twin_model: str
    plant_edit: tuple[str, str, tuple[str, ...]]
    truth: tuple[str, Callable[[np.ndarray], np.ndarray]]
    inputs: Mapping[str, tuple[str, Callable[[np.ndarray], np.ndarray]]]
    outputs: Mapping[str, tuple[str, float]]
    parameters: tuple[tuple[str, float, float, float], ...]
    fixed: Mapping[str, float] = field(default_factory=dict)
    sample_time: float = 60.0
    hours: float = 24.0
    training_hours: float = 8.0
    initial: str = "steady"


# --------------------------------------------------------------------------- the wall (the tutorial's)

_DAY = 86400.0


def _wall_inside(t: np.ndarray) -> np.ndarray:
    """21 degC by day, 17 degC from 22:00 to 06:00, with half-hour ramps between."""
    hour = (t / 3600.0) % 24.0
    day = np.clip((hour - 5.5) / 0.5, 0.0, 1.0) * np.clip((22.5 - hour) / 0.5, 0.0, 1.0)
    return 273.15 + 17.0 + 4.0 * day


def _wall_outside(t: np.ndarray) -> np.ndarray:
    """A daily swing of +-6 K around 5 degC (warmest at 15:00) and a slow front of the weather."""
    return (273.15 + 5.0 + 6.0 * np.sin(2.0 * math.pi * (t / 3600.0 - 9.0) / 24.0)
            + 3.0 * np.sin(2.0 * math.pi * t / (3.3 * _DAY)))


def _wall_r2(t: np.ndarray) -> np.ndarray:
    """The insulation's resistance falls by 30 % over three days (it gets wet)."""
    return 0.04 * (1.0 - 0.3 * np.clip(t / (3.0 * _DAY), 0.0, 1.0))


def _ramp_down(start: float, fraction: float, duration: float) -> Callable[[np.ndarray], np.ndarray]:
    """``start`` falling linearly by *fraction* of itself over *duration* seconds, then held."""
    return lambda t: start * (1.0 - fraction * np.clip(np.asarray(t, dtype=float) / duration, 0.0, 1.0))


CASES: dict[str, OwnCase] = {
    "wall": OwnCase(
        name="wall",
        title="a building wall (RCWall.Wall, the user's package on Modelica.Thermal.HeatTransfer), its "
              "insulation getting wet",
        twin_path="examples/own-model/RCWall", twin_model="RCWall.Wall",
        plant_edit=(
            "Modelica.Thermal.HeatTransfer.Components.ThermalResistor thermalResistor2(R = R2)",
            "OwnPlants.VariableResistor thermalResistor2",
            ("thermalResistor2.R = R2 * (1 - 0.3 * min(time / 259200, 1));",),
        ),
        truth=("R2", _wall_r2),
        inputs={"TI-IN": ("T_in", _wall_inside), "TI-OUT": ("T_out", _wall_outside)},
        outputs={"TI-WALL": ("T_wall", 0.05)},
        parameters=(("R1", 0.01, 0.008, 0.013), ("R2", 0.05, 0.01, 0.1)),  # the tutorial's spec
        fixed={"C": 2e6},
        sample_time=300.0, hours=72.0, training_hours=24.0,
    ),
    # The MSL's own examples, unchanged, as the twins: their sources are constant (no measured inputs) and
    # their time constants a fraction of a second, so the runs are minutes sampled at 50 ms; the plant's
    # conductance falls by 30 % over the run, by 6 % at the end of the training window.
    "cooling": OwnCase(
        name="cooling",
        title="Modelica.Thermal.FluidHeatFlow.Examples.SimpleCooling, its convection fouling",
        twin_path="MSL", twin_model="Modelica.Thermal.FluidHeatFlow.Examples.SimpleCooling",
        plant_edit=("Modelica.Blocks.Sources.Constant thermalConductance(k=1)",
                    "Modelica.Blocks.Sources.Ramp thermalConductance(offset=1, height=-0.3, duration=300)", ()),
        truth=("thermalConductance.k", _ramp_down(1.0, 0.3, 300.0)),
        inputs={},
        outputs={"TI-SRC": ("heatCapacitor.T", 0.02), "TI-COOL": ("pipe.T", 0.02)},
        parameters=(("thermalConductance.k", 1.0, 0.3, 2.0),),
        sample_time=0.05, hours=300.0 / 3600.0, training_hours=60.0 / 3600.0, initial="model",
    ),
    "indirect": OwnCase(
        name="indirect",
        title="Modelica.Thermal.FluidHeatFlow.Examples.IndirectCooling, its cooler fouling on the inner side",
        twin_path="MSL", twin_model="Modelica.Thermal.FluidHeatFlow.Examples.IndirectCooling",
        plant_edit=("Modelica.Blocks.Sources.Constant innerGc(k=2)",
                    "Modelica.Blocks.Sources.Ramp innerGc(offset=2, height=-0.6, duration=300)", ()),
        truth=("innerGc.k", _ramp_down(2.0, 0.3, 300.0)),
        inputs={},
        outputs={"TI-SRC": ("heatCapacitor.T", 0.02), "TI-INNER": ("pipe1.T", 0.02)},
        parameters=(("thermalConductor.G", 1.0, 0.3, 2.0), ("innerGc.k", 2.0, 0.5, 4.0)),
        sample_time=0.05, hours=300.0 / 3600.0, training_hours=60.0 / 3600.0, initial="model",
    ),
}


# --------------------------------------------------------------------------- the plant and its data

def plant_package(case: OwnCase, twin_source: Path, libraries: tuple[Path, ...]) -> str:
    """The Modelica text of package ``OwnPlants`` with the plant variant ``OwnPlants.Plant`` of *case*'s twin.

    The twin's class text (its names written in full, annotations left out: the same reading
    gen-trackingbox makes of a library class) with the case's one edit: a component swapped for
    one whose parameter is driven, and the equation that drives it.
    """
    index = library_index(twin_source, libraries)
    text = _class_text(index, case.twin_model, "Plant")
    old, new, equations = case.plant_edit
    pattern = r"\s+".join(re.escape(part) for part in old.split())
    found = re.search(pattern, text)
    if found is None:
        raise ValueError(f"the twin {case.twin_model} has no declaration {old!r} to replace in its plant")
    text = text[:found.start()] + new + text[found.end():]
    at = text.index("equation") + len("equation")
    text = text[:at] + "".join(f"\n    {eq}" for eq in equations) + text[at:]
    return (f"within;\npackage OwnPlants \"The plant of the own-model case {case.name} (made by "
            f"trackingbox.testing.own_models)\"\n{_PLANT_CLASSES}{text}end OwnPlants;\n")


#: classes the plants use for a degrading parameter
_PLANT_CLASSES = """model VariableResistor "A thermal resistance that changes in time"
  extends Modelica.Thermal.HeatTransfer.Interfaces.Element1D;
  Modelica.Blocks.Interfaces.RealInput R(unit = "K/W") "Thermal resistance";
equation
  dT = R * Q_flow;
end VariableResistor;
model VariableConductor "A thermal conductance that changes in time"
  extends Modelica.Thermal.HeatTransfer.Interfaces.Element1D;
  Modelica.Blocks.Interfaces.RealInput G(unit = "W/K") "Thermal conductance";
equation
  Q_flow = G * dT;
end VariableConductor;
"""


def _iso(t: np.ndarray) -> list[str]:
    """ISO 8601 UTC times of *t* (s from the first sample), with milliseconds where a sample needs them."""
    start = datetime(2026, 3, 2, tzinfo=timezone.utc)
    stamps = [start + timedelta(seconds=round(float(s), 3)) for s in t]
    if all(stamp.microsecond == 0 for stamp in stamps):
        return [stamp.strftime("%Y-%m-%dT%H:%M:%SZ") for stamp in stamps]
    return [stamp.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z" for stamp in stamps]


def write_historian(case: OwnCase, out: Path, *, msl: Path | None = None, seed: int = 1) -> Path:
    """Compile *case*'s plant, simulate it and write ``historian.csv`` and ``truth.json`` into *out*.

    Returns the historian's path. The twin's source is looked for relative to the repository
    (``twin_path``) or is the MSL (``"MSL"``).
    """
    msl = Path(msl) if msl is not None else default_msl()
    twin_source = msl if case.twin_path == "MSL" else repository_root() / case.twin_path
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t = np.arange(0.0, case.hours * 3600.0 + case.sample_time / 2, case.sample_time)
    with tempfile.TemporaryDirectory(prefix="own-plant-") as tmp:
        libs = (msl,) if twin_source == msl else (msl, twin_source)
        plant = Path(tmp) / "OwnPlants.mo"
        plant.write_text(plant_package(case, twin_source, libs), encoding="utf-8")
        fmu = compile_model(plant, "OwnPlants.Plant", backend="embedded", output=Path(tmp) / "plant.fmu",
                            libraries=libs).fmu
        table = pd.DataFrame({"time": t, **{name: fn(t) for name, fn in case.inputs.values()}})
        with FMUModel(fmu, tolerance=1e-8) as model:
            stepper = model.stepper(parameters=dict(case.fixed), inputs=table if case.inputs else None)
            if case.initial == "steady":
                stepper.settle()
            names = [v for v, _ in case.outputs.values()]
            rows = [stepper.get(names)]
            for tk in t[1:]:
                stepper.step(float(tk))
                rows.append(stepper.get(names))
    values = np.asarray(rows)
    rng = np.random.default_rng(seed)
    columns: dict[str, object] = {"time": _iso(t)}
    for tag, (_, fn) in case.inputs.items():
        columns[tag] = np.round(fn(t) + rng.normal(0.0, 0.02, t.size), 4)
    for j, (tag, (_, sigma)) in enumerate(case.outputs.items()):
        columns[tag] = np.round(values[:, j] + rng.normal(0.0, sigma, t.size), 4)
    path = out / "historian.csv"
    pd.DataFrame(columns).to_csv(path, index=False)
    name, law = case.truth
    (out / "truth.json").write_text(json.dumps({
        "case": case.name, "parameter": name, "seed": seed,
        "value": {"start": float(law(t[:1])[0]), "end": float(law(t[-1:])[0])},
        "training_mean": float(np.mean(law(t[t < case.training_hours * 3600.0])))}, indent=2) + "\n",
        encoding="utf-8")
    return path


def _toml_value(value: object) -> str:
    if isinstance(value, str):
        return json.dumps(value)
    return repr(float(value))


def write_spec(case: OwnCase, out: Path, *, twin: str = "twin.fmu", msl: Path | None = None) -> Path:
    """Write ``spec.toml`` for *case* into *out*: the smallest spec the tutorial teaches, for this case.

    The twin FMU *twin* and ``historian.csv`` are named relative to *out*; the twin's source is the MSL
    (``twin_path == "MSL"``) or the repository's package, with the MSL as its library.
    """
    msl = Path(msl) if msl is not None else default_msl()
    out = Path(out)
    source = msl if case.twin_path == "MSL" else repository_root() / case.twin_path
    lines = [f"twin = {_toml_value(twin)}", 'measurements = "historian.csv"',
             f"sample_time = {_toml_value(case.sample_time)}", "",
             "[source]", f"path = {_toml_value(str(source))}", f"model = {_toml_value(case.twin_model)}"]
    if source != msl:
        lines.append(f"libraries = [{_toml_value(str(msl))}]")
    if case.inputs:
        lines += ["", "[inputs]"] + [f"{_toml_value(tag)} = {_toml_value(name)}"
                                     for tag, (name, _) in case.inputs.items()]
    lines += ["", "[outputs]"] + [f"{_toml_value(tag)} = {_toml_value(name)}"
                                  for tag, (name, _) in case.outputs.items()]
    for name, start, low, high in case.parameters:
        lines += ["", "[[parameters]]", f"name = {_toml_value(name)}", f"start = {_toml_value(start)}",
                  f"min = {_toml_value(low)}", f"max = {_toml_value(high)}"]
    if case.fixed:
        lines += ["", "[fixed]"] + [f"{_toml_value(name)} = {_toml_value(v)}" for name, v in case.fixed.items()]
    split, end = case.training_hours * 3600.0, case.hours * 3600.0
    lines += ["", "[windows]", f"training = [0.0, {_toml_value(split)}]",
              f"validation = [{_toml_value(split)}, {_toml_value(end)}]",
              "", "[data]", f"initial = {_toml_value(case.initial)}", ""]
    path = out / "spec.toml"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path
