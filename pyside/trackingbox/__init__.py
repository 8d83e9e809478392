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

The names are bound here from the modules that define them. Three of them are
also the names of a subpackage or module (``generate``, ``validate``,
``diagnose``): each is bound after its module is loaded, so the function wins.
Modules of the package import from the defining module, never from here.
"""
from __future__ import annotations

from . import stages
from .analysis.pair_stage import PairingResult, PairSettings, pair, spec_pairs
from .data import MeasurementView
from .diagnose.stage import DiagnoseSettings, DiagnosisResult, diagnose
from .estimation import EstimationResult, estimate
from .generate.generator import GenerateResult, compile_generated, generate
from .spec import Spec, load_spec
from .tracking.runtime import TrackingResult, track
from .validate import ValidationResult, validate
from .version import __version__

__all__ = [
    "__version__", "Spec", "load_spec", "estimate", "EstimationResult", "pair", "PairSettings", "PairingResult",
    "spec_pairs", "track", "TrackingResult", "generate", "compile_generated", "GenerateResult", "validate",
    "ValidationResult", "MeasurementView", "diagnose", "DiagnoseSettings", "DiagnosisResult", "stages",
]
