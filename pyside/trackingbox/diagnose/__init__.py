"""Discrepancy diagnosis: where the twin and the plant disagree, which missing effect explains it, the patch.

``diagnose(spec, settings)`` (:mod:`.stage`) runs :mod:`.residuals` (where),
:mod:`.screen` (which effect, cheaply), :mod:`.fit` (the best few through their
patched, compiled twin), :mod:`.judge` (held-out verdict); :mod:`.library`
holds the effect entries, their targets and the patch rendering.
"""
from __future__ import annotations

from .stage import DiagnoseSettings, DiagnosisResult, diagnose

__all__ = ["DiagnoseSettings", "DiagnosisResult", "diagnose"]
