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

The other names are imported on first use.
"""
from __future__ import annotations

from importlib import import_module
from typing import Any

from .version import __version__

#: Public name -> module that defines it.
_API = {
    "Spec": "spec",
    "load_spec": "spec",
    "estimate": "estimation",
    "EstimationResult": "estimation",
    "pair": "analysis.pair_stage",
    "PairSettings": "analysis.pair_stage",
    "PairingResult": "analysis.pair_stage",
    "spec_pairs": "analysis.pair_stage",
    "track": "tracking.runtime",
    "TrackingResult": "tracking.runtime",
    "compile_generated": "generate.generator",
    "GenerateResult": "generate.generator",
    "ValidationResult": "validate",
    "MeasurementView": "data",
    "DiagnoseSettings": "diagnose.stage",
    "DiagnosisResult": "diagnose.stage",
}

# ``generate`` and ``validate`` are also the names of a subpackage and a module: loading those sets the
# package attribute to the module, so the functions are bound here, after the modules are loaded.
from .generate.generator import generate  # noqa: E402
from .validate import validate  # noqa: E402
from .diagnose.stage import diagnose  # noqa: E402

__all__ = ["__version__", "generate", "validate", "diagnose", *_API]


def __getattr__(name: str) -> Any:
    if name not in _API:
        raise AttributeError(f"module 'trackingbox' has no attribute {name!r}")
    value = getattr(import_module(f".{_API[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
