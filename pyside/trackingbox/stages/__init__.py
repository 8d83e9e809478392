"""The six stages, each a module with one contract.

======== ========================== =============================================
module   settings                   result (``to_json()``)
======== ========================== =============================================
estimate :class:`EstimateSettings`  :class:`~trackingbox.estimation.EstimationResult`
pair     :class:`PairSettings`      :class:`~trackingbox.analysis.pair_stage.PairingResult`
track    :class:`TrackSettings`     :class:`~trackingbox.tracking.result.TrackingResult`
generate :class:`GenerateSettings`  :class:`~trackingbox.generate.generator.GenerateResult`
validate :class:`ValidateSettings`  :class:`~trackingbox.validate.ValidationResult`
diagnose :class:`DiagnoseSettings`  :class:`~trackingbox.diagnose.stage.DiagnosisResult`
======== ========================== =============================================

Each module has ``run(spec, settings, *, progress=None) -> Result``: a loaded
:class:`~trackingbox.spec.Spec`, a frozen settings dataclass, one progress callable of the
:class:`~trackingbox.stages.contract.Progress` shape. The commands build the settings from
their arguments with :func:`~trackingbox.stages.contract.settings_from_args` and call ``run``;
``scripts/demo`` and a notebook call the same::

    from trackingbox.stages import estimate, track
    result = estimate.run(spec, estimate.EstimateSettings(workers=2))
    run = track.run(spec, track.TrackSettings(out_dir="case1/track"))
"""
from __future__ import annotations

from . import diagnose, estimate, generate, pair, track, validate
from .contract import Progress, Result, settings_from_args
from .diagnose import DiagnoseSettings
from .estimate import EstimateSettings
from .generate import GenerateSettings
from .pair import PairSettings
from .track import TrackSettings
from .validate import ValidateSettings

__all__ = ["diagnose", "estimate", "generate", "pair", "track", "validate", "Progress", "Result",
           "settings_from_args", "DiagnoseSettings", "EstimateSettings", "GenerateSettings", "PairSettings",
           "TrackSettings", "ValidateSettings"]
