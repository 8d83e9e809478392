"""Generic bench-case machinery: compile, simulate the plant, add sensor noise, write the case.

A bench is described by a :class:`BenchDefinition` (which Modelica classes, which
sensors with which noise, which candidate parameters, and a scenario function);
:func:`build_case` turns it into a directory::

    plant.fmu          the "physical" plant (the truth)
    twin.fmu           the digital twin to be tracked
    measurements.csv   time (s) + measured tags (inputs and outputs, with sensor noise)
    plant_inputs.csv   time (s) + the plant's true (noise-free) inputs, FMU names
    spec.toml          the tracking specification (loads with trackingbox.spec.load_spec)
    truth.json         true plant parameter values, seed, overrides (not read by the spec);
                       for a hidden-effect case also what is hidden (``hidden``)

A *hidden-effect case* (:class:`HiddenCase`, ``build_case(..., hidden=NAME)``)
simulates a plant variant that carries an effect the twin lacks (the suite of
``trackingbox diagnose``); the spec is that of the plain bench, the twin the
bench's *suite twin* (:attr:`BenchDefinition.suite_twin_model`) where it names
one, else the bench's twin. ``build_case(..., suite_twin=True)`` writes the plain
bench against the suite twin (the suite's no-effect case), ``suite_twin=False`` a
hidden case against the bench's own twin.

Nothing is written into the output directory until every step has succeeded.
"""
from __future__ import annotations

import json
import logging
import math
import os
import shutil
import tempfile
import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from ..compiler import (
    compile_model,
    library_path,
)
from ..errors import FMUError, SimulationError, TrackingError, did_you_mean
from ..fmu import read_info
from ..io import atomic_path, write_text_atomic
from ..simulation.models import open_model
from ..spec import (
    DataRules,
    ParameterSpec,
    SourceSpec,
    Spec,
    StateSpec,
    TrackingSettings,
    check_against_fmu,
    dump_spec,
    load_spec,
    loads_spec,
)

log = logging.getLogger(__name__)

SensorKind = Literal["temperature", "flow", "level", "pressure", "power", "other"]

#: Default sensor noise: (standard deviation, relative?) per kind. Temperatures
#: 0.1 K, flows 1 % of reading, levels 5 mm, pressures 0.2 % of reading.
NOISE: dict[str, tuple[float, bool]] = {
    "temperature": (0.1, False),
    "flow": (0.01, True),
    "level": (0.005, False),
    "pressure": (0.002, True),
    "power": (0.01, True),
    "other": (0.0, False),
}

Scenario = Callable[[np.ndarray, np.random.Generator, float], dict[str, np.ndarray]]


@dataclass(frozen=True)
class Sensor:
    """A measured tag: which FMU variable it reads and how noisy it is.

    Attributes
    ----------
    tag : str
        DCS-style tag, e.g. ``TI-102``.
    plant : str
        Plant FMU variable it measures.
    twin : str
        Twin FMU variable that simulates it (or the twin input it drives).
    kind : SensorKind
        Sets the default noise (:data:`NOISE`).
    sigma : float or None
        Override of the noise standard deviation (absolute, or relative when
        ``relative``).
    relative : bool or None
        Override: *sigma* is a fraction of the reading.
    """

    tag: str
    plant: str
    twin: str
    kind: SensorKind
    sigma: float | None = None
    relative: bool | None = None

    @property
    def noise(self) -> tuple[float, bool]:
        """(standard deviation, relative?) of this sensor."""
        sigma, relative = NOISE[self.kind]
        return (self.sigma if self.sigma is not None else sigma,
                self.relative if self.relative is not None else relative)


@dataclass(frozen=True)
class HiddenCase:
    """A plant variant with an effect the twin lacks (``Benches.<Bench>.Hidden.<Model>``).

    Attributes
    ----------
    name : str
        Case name on the command line (``--hidden NAME``).
    model : str
        Full class name of the plant variant.
    effect : str or None
        Id of the library effect that describes it (``None``: outside the library).
    target : str or None
        Component instance (process effects) or tag (sensor effects) it acts on.
    description : str
        What is hidden, in its own functional form.
    sensors : mapping
        Tag -> plant variable that replaces the plain plant's (a faulty sensor's reading).
    affected : tuple of str
        Output tags the effect shows in (the NRMSE criterion of the suite).
    also : tuple of str
        Further targets the plant carries the same effect on (the borate's boiling-point rise is in
        the effect and in the flash tank): naming the effect on any of them is right.
    instrument : str or None
        The tag of the faulty instrument when the effect is one meter's error: a generic sensor
        entry on that tag (``sensor-bias@QI-6150`` for a ``ds-meter`` case) names the right
        instrument with another entry's form; the suite reports it apart, neither right nor wrong.
    others : tuple of (str, str)
        Further (effect, target) pairs the plant carries at once (a two-effect case): naming any
        of them is right too.
    """

    name: str
    model: str
    effect: str | None
    target: str | None
    description: str
    sensors: Mapping[str, str] = field(default_factory=dict)
    affected: tuple[str, ...] = ()
    also: tuple[str, ...] = ()
    instrument: str | None = None
    others: tuple[tuple[str, str], ...] = ()

    @property
    def targets(self) -> tuple[str, ...]:
        """Every target the plant carries the effect on (``target`` first)."""
        return (self.target, *self.also) if self.target else ()

    def to_json(self) -> dict[str, Any]:
        return {"case": self.name, "model": self.model, "effect": self.effect, "target": self.target,
                "targets": list(self.targets), "instrument": self.instrument,
                "description": self.description, "sensors": dict(self.sensors), "affected": list(self.affected),
                "others": [list(o) for o in self.others]}


@dataclass(frozen=True)
class BenchDefinition:
    """Everything that makes one bench case.

    The scenario function takes the sample times (s, starting at 0, *including*
    the warm-up), a seeded generator and the warm-up length, and returns the plant
    input trajectories by plant FMU input name (held constant through the warm-up).
    """

    name: str
    title: str
    plant_model: str
    twin_model: str
    sample_time: float
    hours: float
    warmup: float
    inputs: tuple[Sensor, ...]
    outputs: tuple[Sensor, ...]
    parameters: tuple[ParameterSpec, ...]
    scenario: Scenario
    fixed: Mapping[str, float] = field(default_factory=dict)
    states: tuple[StateSpec, ...] = ()
    #: the benches' plants are measured after a warm-up with their inputs held: their twins start from
    #: their steady state at the first sample (``[data] initial = "steady"``)
    data: DataRules = field(default_factory=lambda: DataRules(initial="steady"))
    tracking: TrackingSettings = field(default_factory=TrackingSettings)
    truth_map: Mapping[str, str] = field(default_factory=dict)
    """Twin candidate parameter -> plant parameter holding its true value, where names differ."""
    hidden: Mapping[str, HiddenCase] = field(default_factory=dict)
    """Hidden-effect cases of this bench, by name."""
    suite_twin_model: str | None = None
    """The twin the hidden-effect suite diagnoses against, where it is not :attr:`twin_model`: a twin
    that lacks nothing but parameter values and the hidden effect (the default: :attr:`twin_model`)."""


@dataclass(frozen=True)
class BenchCase:
    """A written bench case: its files and the truth behind it."""

    name: str
    directory: Path
    spec: Path
    twin_fmu: Path
    plant_fmu: Path
    measurements: Path
    plant_inputs: Path
    truth_file: Path
    truth: dict[str, float]
    """True plant values of the candidate parameters (twin names)."""
    plant_parameters: dict[str, float]
    """Every tunable plant parameter as simulated (declared start or override)."""
    seed: int
    hours: float

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready summary (paths as strings)."""
        return {
            "bench": self.name, "directory": str(self.directory), "spec": str(self.spec),
            "twin_fmu": str(self.twin_fmu), "plant_fmu": str(self.plant_fmu),
            "measurements": str(self.measurements), "plant_inputs": str(self.plant_inputs),
            "truth_file": str(self.truth_file), "truth": self.truth, "seed": self.seed,
            "hours": self.hours,
        }


# --------------------------------------------------------------------------- helpers

def _compile(model: str, output: Path) -> Path:
    t0 = _time.perf_counter()
    result = compile_model(library_path(), model, output=output)
    log.info("compiled %s -> %s in %.1f s", model, result.fmu, _time.perf_counter() - t0)
    return Path(result.fmu)


def _library_path() -> Path | None:
    try:
        return Path(library_path())
    except (ImportError, AttributeError):  # pragma: no cover - compiler not installed
        return None


def _tunable_parameters(info: Any) -> dict[str, Any]:
    """name -> Variable for the FMU's settable Real parameters."""
    return {v.name: v for v in info.variables
            if v.causality == "parameter" and v.variability in ("tunable", "fixed")
            and str(v.type).lower() in ("real", "float64", "float32")}


def check_overrides(overrides: Mapping[str, float], info: Any, where: str) -> dict[str, float]:
    """Check plant parameter overrides against the plant FMU: known names, declared bounds.

    Raises
    ------
    FMUError
        Listing every unknown name (with did-you-mean) and every value outside the
        parameter's declared ``min``/``max``.
    """
    params = _tunable_parameters(info)
    problems = []
    out: dict[str, float] = {}
    for name, value in overrides.items():
        value = float(value)
        var = params.get(name)
        if var is None:
            problems.append(f"unknown plant parameter {name!r} in {where}{did_you_mean(name, params)}")
            continue
        if not math.isfinite(value):
            problems.append(f"value {value!r} for plant parameter {name!r} is not finite")
            continue
        lo = var.min if var.min is not None else -math.inf
        hi = var.max if var.max is not None else math.inf
        if not float(lo) <= value <= float(hi):
            problems.append(f"value {value!r} for plant parameter {name!r} is outside its declared "
                            f"range [{lo}, {hi}] in {where}")
            continue
        out[name] = value
    if problems:
        raise FMUError("; ".join(problems))
    return out


def add_noise(values: np.ndarray, sigma: float, relative: bool, rng: np.random.Generator) -> np.ndarray:
    """*values* plus Gaussian noise of standard deviation *sigma* (× ``|values|`` when *relative*)."""
    scale = sigma * np.abs(values) if relative else np.full_like(values, sigma, dtype=float)
    return values + scale * rng.standard_normal(values.shape)


def _write_csv(frame: pd.DataFrame, target: Path) -> None:
    with atomic_path(target) as tmp:
        frame.to_csv(tmp, index=False, float_format="%.9g")


# --------------------------------------------------------------------------- main

def build_case(definition: BenchDefinition, out: str | os.PathLike[str], *, seed: int = 0,
               overrides: Mapping[str, float] | None = None, hours: float | None = None,
               plant_fmu: str | os.PathLike[str] | None = None,
               twin_fmu: str | os.PathLike[str] | None = None,
               hidden: str | None = None, noise_scale: float = 1.0,
               suite_twin: bool | None = None) -> BenchCase:
    """Generate one bench case into directory *out* (see the module docstring for the files).

    Parameters
    ----------
    definition : BenchDefinition
    out : path-like
        Output directory (created; existing case files are replaced).
    seed : int
        Seeds the scenario and the sensor noise.
    overrides : mapping, optional
        Plant parameter values replacing the plant's declared starts (the truth).
    hours : float, optional
        Length of the measured period (default: the bench's).
    plant_fmu, twin_fmu : path-like, optional
        Already-compiled FMUs of the bench's plant and twin classes, copied instead
        of compiling.
    hidden : str, optional
        A hidden-effect case of the bench (:class:`HiddenCase`): its plant variant
        is simulated (and *plant_fmu*, if given, must be that variant's FMU).
    noise_scale : float
        Factor on every sensor's noise standard deviation (default 1).
    suite_twin : bool, optional
        Use the bench's suite twin (:attr:`BenchDefinition.suite_twin_model`, where it names one)
        instead of its twin; default: for hidden-effect cases only. *twin_fmu*, if given, must be
        the FMU of the twin used.

    Returns
    -------
    BenchCase

    Raises
    ------
    FMUError
        An override names an unknown plant parameter or is outside its declared range.
    CompileError, SimulationError
        Compiling or simulating the plant failed.
    """
    out = Path(out).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise TrackingError(f"output directory {out} of bench {definition.name!r} exists and is not a directory")
    hours = float(definition.hours if hours is None else hours)
    if not hours > 0:
        raise TrackingError(f"bench {definition.name!r}: --hours must be > 0, got {hours}")
    for given, what in ((plant_fmu, "plant"), (twin_fmu, "twin")):
        if given is not None and not Path(given).is_file():
            raise FMUError(f"{what} FMU {given} for bench {definition.name!r} does not exist")
    overrides = dict(overrides or {})
    definition, case_hidden, suite = _variant(definition, hidden, suite_twin)
    if not (math.isfinite(noise_scale) and noise_scale >= 0):
        raise TrackingError(f"bench {definition.name!r}: --noise-scale must be a number >= 0, got {noise_scale}")
    seeds = np.random.SeedSequence(int(seed)).spawn(2)
    scenario_rng, noise_rng = (np.random.default_rng(s) for s in seeds)

    with tempfile.TemporaryDirectory(prefix=f"bench-{definition.name}-") as tmpdir:
        stage = Path(tmpdir)
        # 1. FMUs (compile once, or copy the given ones) -----------------------
        staged_plant = _stage_fmu(definition.plant_model, plant_fmu, stage, "plant")
        plant_info = read_info(staged_plant)
        overrides = check_overrides(overrides, plant_info, f"the {definition.name} plant "
                                    f"({definition.plant_model})")
        staged_twin = _stage_fmu(definition.twin_model, twin_fmu, stage, "twin")

        # 2. scenario over warm-up + measured period ----------------------------
        dt = definition.sample_time
        warmup = definition.warmup
        n_meas = int(round(hours * 3600.0 / dt))
        n_warm = int(round(warmup / dt))
        t_all = np.arange(n_warm + n_meas + 1) * dt
        true_inputs = definition.scenario(t_all, scenario_rng, warmup)
        frame = pd.DataFrame({"time": t_all, **true_inputs})

        # 3. plant simulation -------------------------------------------------
        plant_vars = [s.plant for s in definition.outputs]
        log.info("simulating the %s plant for %.1f h (+%.1f h warm-up)", definition.name, hours, warmup / 3600)
        result, _, _ = simulate_plant(staged_plant, t_all, frame, overrides, plant_vars, definition.name)

        # 4. measurements = true signals on the measured period + sensor noise ------
        keep = slice(n_warm, None)
        t_meas = t_all[keep] - warmup
        measurements = noisy_measurements(t_meas, definition.inputs, definition.outputs, true_inputs, result, keep,
                                          noise_scale, noise_rng)
        plant_inputs = frame.iloc[keep].copy()
        plant_inputs["time"] = t_meas

        # 5. truth ------------------------------------------------------------
        truth, plant_params = _truth(definition, plant_info, overrides)

        # 6. spec ---------------------------------------------------------------
        lib = _library_path()
        half = round(n_meas / 2) * dt
        end = n_meas * dt
        spec = Spec(
            path=out / "spec.toml", twin=out / "twin.fmu", measurements=out / "measurements.csv",
            sample_time=dt,
            source=SourceSpec(path=lib, model=definition.twin_model) if lib is not None else None,
            inputs={s.tag: s.twin for s in definition.inputs},
            # measured states (tank levels) are followed by state compensation, not pairs
            outputs={s.tag: s.twin for s in definition.outputs
                     if s.tag not in {st.tag for st in definition.states}},
            parameters=definition.parameters, fixed=dict(definition.fixed),
            windows={"training": (0.0, half), "validation": (half, end)},
            data=definition.data, states=definition.states, tracking=definition.tracking,
        )
        command = f"trackingbox bench {definition.name}" + (f" --hidden {hidden}" if hidden else "") + (
            f" --noise-scale {noise_scale:g}" if noise_scale != 1.0 else "") + (
            f" --{'' if suite else 'no-'}suite-twin" if suite_twin is not None else "")
        header = (f"{definition.title}: generated by `{command}`\n"
                  f"seed = {seed}, hours = {hours:g}, plant overrides = "
                  f"{json.dumps(overrides) if overrides else 'none'}\n"
                  f"true plant values are in truth.json (not read by the spec)")
        spec_text = dump_spec(spec, header=header)
        # columns in the order of the spec's tags (inputs, outputs, measured states)
        order = ["time", *spec.tags]
        measurements = measurements[order + [c for c in measurements.columns if c not in order]]
        truth_doc = {"bench": definition.name, "seed": int(seed), "hours": hours,
                     "plant_model": definition.plant_model, "twin_model": definition.twin_model,
                     "overrides": overrides, "parameters": truth, "plant_parameters": plant_params,
                     "noise_scale": float(noise_scale),
                     "hidden": case_hidden.to_json() if case_hidden is not None else None}

        # the spec must fit the twin it names before anything is published
        check_against_fmu(loads_spec(spec_text, out / "spec.toml", check_files=False), read_info(staged_twin))

        # 7. publish: every file atomically, FMUs first, spec last ----------------
        out.mkdir(parents=True, exist_ok=True)
        for src, name in ((staged_plant, "plant.fmu"), (staged_twin, "twin.fmu")):
            with atomic_path(out / name) as tmp:
                shutil.copyfile(src, tmp)
        _write_csv(measurements, out / "measurements.csv")
        _write_csv(plant_inputs, out / "plant_inputs.csv")
        write_text_atomic(out / "truth.json", json.dumps(truth_doc, indent=2, sort_keys=True) + "\n")
        write_text_atomic(out / "spec.toml", spec_text)

    load_spec(out / "spec.toml")  # the case we wrote must load cleanly
    log.info("wrote bench case %s to %s", definition.name, out)
    return BenchCase(name=definition.name, directory=out, spec=out / "spec.toml",
                     twin_fmu=out / "twin.fmu", plant_fmu=out / "plant.fmu",
                     measurements=out / "measurements.csv", plant_inputs=out / "plant_inputs.csv",
                     truth_file=out / "truth.json", truth=truth, plant_parameters=plant_params,
                     seed=int(seed), hours=hours)


def _variant(definition: BenchDefinition, hidden: str | None, suite_twin: bool | None
             ) -> tuple[BenchDefinition, HiddenCase | None, bool]:
    """The bench as the case simulates it: the hidden-effect plant, the suite twin (and whether it is used)."""
    case_hidden: HiddenCase | None = None
    if hidden is not None:
        if hidden not in definition.hidden:
            raise TrackingError(f"unknown hidden-effect case {hidden!r} of bench {definition.name!r}"
                                f"{did_you_mean(hidden, list(definition.hidden))}; choose one of "
                                f"{', '.join(definition.hidden) or '(none)'}")
        case_hidden = definition.hidden[hidden]
        definition = replace(definition, plant_model=case_hidden.model, outputs=tuple(
            replace(s, plant=case_hidden.sensors.get(s.tag, s.plant)) for s in definition.outputs))
    suite = (hidden is not None) if suite_twin is None else bool(suite_twin)
    if suite and definition.suite_twin_model is not None:
        definition = replace(definition, twin_model=definition.suite_twin_model)
    return definition, case_hidden, suite


def _stage_fmu(model: str, given: str | os.PathLike[str] | None, stage: Path, name: str) -> Path:
    """``stage/<name>.fmu``: a copy of the *given* FMU, else *model* compiled once."""
    staged = stage / f"{name}.fmu"
    if given is not None:
        shutil.copyfile(given, staged)
    else:
        built = _compile(model, stage / "build" / f"{name}.fmu")
        shutil.copyfile(built, staged)
    return staged


def noisy_measurements(t_meas: np.ndarray, inputs: Sequence[Sensor], outputs: Sequence[Sensor],
                       true_inputs: Mapping[str, Any], result: pd.DataFrame, keep: slice, noise_scale: float,
                       noise_rng: np.random.Generator) -> pd.DataFrame:
    """The measurements: the true signals on the measured period plus each sensor's noise (inputs, then outputs)."""
    columns: dict[str, np.ndarray] = {"time": t_meas}
    for s in inputs:
        sigma, rel = s.noise
        columns[s.tag] = add_noise(np.asarray(true_inputs[s.plant], float)[keep], sigma * noise_scale, rel,
                                   noise_rng)
    for s in outputs:
        sigma, rel = s.noise
        columns[s.tag] = add_noise(result[s.plant].to_numpy(float)[keep], sigma * noise_scale, rel, noise_rng)
    return pd.DataFrame(columns)


def simulate_plant(fmu: Path, t_all: np.ndarray, frame: pd.DataFrame, overrides: Mapping[str, float],
                   variables: list[str], bench: str) -> tuple[pd.DataFrame, float, float]:
    """The plant over the scenario on the grid *t_all* (its variables *variables*), its wall and CPU seconds."""
    t0, c0 = _time.perf_counter(), _time.process_time()
    model = open_model(fmu)
    try:
        result = model.simulate(stop_time=float(t_all[-1]), output_interval=float(t_all[1] - t_all[0]),
                                inputs=frame, parameters=dict(overrides), outputs=variables)
    finally:
        model.close()
    seconds, cpu = _time.perf_counter() - t0, _time.process_time() - c0
    log.info("plant simulation took %.1f s (%.1f s CPU)", seconds, cpu)
    return _on_grid(result, t_all, variables, bench), seconds, cpu


def _truth(definition: BenchDefinition, plant_info: Any, overrides: Mapping[str, float]
           ) -> tuple[dict[str, float], dict[str, float]]:
    """The twin parameters' true values (through the bench's truth map) and the plant's tunable parameters."""
    plant_params = {name: float(v.start) for name, v in _tunable_parameters(plant_info).items()
                    if v.start is not None}
    plant_params.update(overrides)
    truth: dict[str, float] = {}
    for p in definition.parameters:
        source = definition.truth_map.get(p.name, p.name)
        if source in plant_params:
            truth[p.name] = plant_params[source]
    return truth, plant_params


def _on_grid(result: pd.DataFrame, t: np.ndarray, names: list[str], bench: str) -> pd.DataFrame:
    """The simulation result at exactly the times *t* (interpolated if the grid differs)."""
    missing = [n for n in names if n not in result.columns]
    if missing:
        raise SimulationError(f"bench {bench!r}: the plant result lacks {missing}")
    rt = result["time"].to_numpy(float)
    if len(rt) == len(t) and np.allclose(rt, t, atol=1e-6 * max(1.0, t[-1])):
        out = result.reset_index(drop=True)
    else:
        # drop duplicate time points (events) keeping the last value, then interpolate
        dedup = result.drop_duplicates(subset="time", keep="last")
        out = pd.DataFrame({"time": t, **{n: np.interp(t, dedup["time"].to_numpy(float),
                                                        dedup[n].to_numpy(float)) for n in names}})
    bad = [n for n in names if not np.all(np.isfinite(out[n].to_numpy(float)))]
    if bad:
        raise SimulationError(f"bench {bench!r}: the plant simulation gave non-finite values for {bad}")
    return out
