"""Bench cases: a "physical" plant and a digital twin, a scenario, noisy measurements, a spec.

Three benches follow the source thesis: ``heat-exchanger`` (counter-flow heat
exchanger, plant ``kht`` differs from the twin's), ``heat-production``
(preheating tank, storage tank, heating unit, heat exchanger to a district-heating
stream; quadratic pressure losses in the plant, linear in the twin) and
``evaporator`` (the last effect of a black-liquor evaporation plant, fouling
through a multi-day run with flow stoppages, measurements as a historian exports
them). ``evaporator-train`` scales the evaporator to a whole train of N effects
(``--effects``, default 7).

>>> from trackingbox.benches import BENCHES
>>> sorted(BENCHES)
['evaporator', 'evaporator-train', 'heat-exchanger', 'heat-production']
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

from ..errors import TrackingError, did_you_mean
from . import evaporator, evaporator_train, heat_exchanger, heat_production
from .base import BenchCase, BenchDefinition, HiddenCase, Sensor, build_case

__all__ = ["BENCHES", "BenchCase", "BenchDefinition", "HiddenCase", "Sensor", "bench_definition", "make_bench"]

#: Bench names the ``bench`` command accepts, with the module that defines each.
BENCHES: dict[str, str] = {
    "heat-exchanger": "heat_exchanger",
    "heat-production": "heat_production",
    "evaporator": "evaporator",
    "evaporator-train": "evaporator_train",
}
_MODULES = {"heat_exchanger": heat_exchanger, "heat_production": heat_production, "evaporator": evaporator,
            "evaporator_train": evaporator_train}


def bench_definition(name: str) -> BenchDefinition:
    """The :class:`BenchDefinition` of bench *name* (did-you-mean on unknown names)."""
    if name not in BENCHES:
        raise TrackingError(f"unknown bench {name!r}{did_you_mean(name, BENCHES)}; "
                                f"choose one of {', '.join(BENCHES)}")
    return _MODULES[BENCHES[name]].DEFINITION


def make_bench(name: str, out: str | os.PathLike[str], seed: int = 0,
               overrides: Mapping[str, float] | None = None, hours: float | None = None, *,
               plant_fmu: str | os.PathLike[str] | None = None,
               twin_fmu: str | os.PathLike[str] | None = None,
               hidden: str | None = None, noise_scale: float = 1.0, effects: int | None = None,
               suite_twin: bool | None = None) -> BenchCase:
    """Generate bench case *name* into directory *out*.

    Parameters
    ----------
    name : {"heat-exchanger", "heat-production", "evaporator", "evaporator-train"}
    out : path-like
        Output directory.
    seed : int
        Seeds the scenario and the sensor noise.
    overrides : mapping, optional
        Plant parameter values (the truth) replacing the plant model's defaults.
    hours : float, optional
        Measured period in hours (default: 8 for the heat exchanger, 24 for heat production,
        72 for the evaporator).
    plant_fmu, twin_fmu : path-like, optional
        Already-compiled FMUs of the bench's plant and twin, reused instead of compiling.
    hidden : str, optional
        Hidden-effect case (``BenchDefinition.hidden``): simulate that plant variant.
    noise_scale : float
        Factor on every sensor's noise.
    effects : int, optional
        Number of effects (``evaporator-train`` only; default 7).
    suite_twin : bool, optional
        Write the case against the bench's suite twin (``BenchDefinition.suite_twin_model``);
        default: for hidden-effect cases only.

    Returns
    -------
    BenchCase
        Paths of the written files and the true parameter values.
    """
    definition = bench_definition(name)
    module = _MODULES[BENCHES[name]]
    takes_effects = name == "evaporator-train"
    if effects is not None and not takes_effects:
        raise TrackingError(f"bench {name!r} has no number of effects (--effects applies to evaporator-train)")
    if hasattr(module, "build"):  # a bench with its own case writer (the evaporator: historian export)
        if suite_twin:
            raise TrackingError(f"bench {name!r} has no suite twin (--suite-twin applies to heat-exchanger and "
                                f"heat-production; the evaporator's hidden-effect cases use its own twin, the "
                                f"train's its twin without the steam-economy candidates)")
        extra: dict[str, Any] = {"effects": effects} if takes_effects and effects is not None else {}
        extra.update(hidden=hidden, noise_scale=noise_scale)
        return module.build(out, seed=seed, overrides=overrides, hours=hours, plant_fmu=plant_fmu,
                            twin_fmu=twin_fmu, **extra)
    return build_case(definition, out, seed=seed, overrides=overrides, hours=hours,
                      plant_fmu=plant_fmu, twin_fmu=twin_fmu, hidden=hidden, noise_scale=noise_scale,
                      suite_twin=suite_twin)
