"""trackingbox: turn a Modelica process model into a tracking simulator.

A tracking simulator runs beside the plant with the plant's control inputs and
keeps adjusting selected model parameters so that its simulated sensors follow
the plant's measurements.

Each stage is one function taking a loaded :class:`Spec` and settings and
returning a frozen result dataclass with ``to_json()``; the ``trackingbox``
commands and ``scripts/demo`` call these, and so can a notebook::

    import trackingbox as tb
    spec = tb.load_spec("case1/spec.toml")
    est = tb.estimate(spec, workers=2)                  # EstimationResult
    pairs = tb.pair(spec, tb.PairSettings())            # PairingResult
    run = tb.track(spec, out_dir="case1/track")         # TrackingResult
    gen = tb.generate(spec, "case1/generated")          # GenerateResult
    fmu = tb.compile_generated(gen).fmu
    val = tb.validate(spec, fmu)                        # ValidationResult
    dia = tb.diagnose(spec, tb.DiagnoseSettings())      # DiagnosisResult

The same stages with one contract each (a settings dataclass, ``run(spec, settings, *,
progress=None)``), as the commands and the demo call them: :mod:`trackingbox.stages`::

    est = tb.stages.estimate.run(spec, tb.stages.EstimateSettings(workers=2))

The names are imported from the modules that define them on first use (so that
``import trackingbox.cli`` and a ``trackingbox compile`` run do not load the
estimation, statistics and simulation stacks). Three of them are also the names
of a subpackage or module (``generate``, ``validate``, ``diagnose``): the function
wins, even after its module was imported. Modules of the package import from the
defining module, never from here.
"""
from __future__ import annotations

import importlib
import sys
import types
from typing import Any

from .version import __version__

#: Public name -> the module defining it.
_HOMES = {
    "Spec": ".spec", "load_spec": ".spec", "estimate": ".estimation", "EstimationResult": ".estimation",
    "pair": ".analysis.pair_stage", "PairSettings": ".analysis.pair_stage", "PairingResult": ".analysis.pair_stage",
    "spec_pairs": ".analysis.pair_stage", "track": ".tracking.runtime", "TrackingResult": ".tracking.runtime",
    "generate": ".generate.generator", "compile_generated": ".generate.generator",
    "GenerateResult": ".generate.generator", "validate": ".validate", "ValidationResult": ".validate",
    "MeasurementView": ".data", "diagnose": ".diagnose.stage", "DiagnoseSettings": ".diagnose.stage",
    "DiagnosisResult": ".diagnose.stage",
}

__all__ = [
    "__version__", "Spec", "load_spec", "estimate", "EstimationResult", "pair", "PairSettings", "PairingResult",
    "spec_pairs", "track", "TrackingResult", "generate", "compile_generated", "GenerateResult", "validate",
    "ValidationResult", "MeasurementView", "diagnose", "DiagnoseSettings", "DiagnosisResult", "stages",
]


def _load(name: str) -> Any:
    return getattr(importlib.import_module(_HOMES[name], __name__), name)


def __getattr__(name: str) -> Any:
    if name == "stages":
        return importlib.import_module(".stages", __name__)
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = _load(name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


def _function_wins(name: str) -> property:
    """``trackingbox.<name>`` is the stage function, not the submodule of the same name that
    importing ``trackingbox.<name>.x`` binds here (the import system's assignment is ignored)."""
    return property(lambda _module: _load(name), lambda _module, _value: None)


class _Package(types.ModuleType):
    generate = _function_wins("generate")
    validate = _function_wins("validate")
    diagnose = _function_wins("diagnose")


sys.modules[__name__].__class__ = _Package
