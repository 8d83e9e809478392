"""The diagnose stage: where the twin and the measurements disagree, which effect explains it, the patch.

``run(spec, DiagnoseSettings(...), progress=...)`` -> :class:`~trackingbox.diagnose.stage.DiagnosisResult`
(the computation: :func:`trackingbox.diagnose.stage.diagnose`).
"""
from __future__ import annotations

from typing import Any

from ..diagnose.stage import DiagnoseSettings, DiagnosisResult, diagnose
from .contract import Progress

__all__ = ["DiagnoseSettings", "DiagnosisResult", "run"]


def run(spec: Any, settings: DiagnoseSettings = DiagnoseSettings(), *,
        progress: Progress | None = None) -> DiagnosisResult:
    """Diagnose with *settings*; *progress* gets ``(stage, done, total)`` of the null fit, screening and fits."""
    return diagnose(spec, settings, progress=progress)
