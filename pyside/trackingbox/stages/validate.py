"""The validate stage: the compiled tracked model on held-out data, against the Python runtime.

``run(spec, ValidateSettings(fmu=...))`` -> :class:`~trackingbox.validate.ValidationResult`
(the computation: :func:`trackingbox.validate.validate`, whose keywords are the settings' fields).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from ..tracking.controllers import Interpolation
from ..validate import ValidationResult, validate
from .contract import Progress

__all__ = ["ValidateSettings", "ValidationResult", "run"]


@dataclass(frozen=True)
class ValidateSettings:
    """Settings of the validate stage (the ``trackingbox validate`` options; see :func:`~trackingbox.validate.validate`)."""

    fmu: Path
    work_dir: Path | None = None
    band: float = 0.05
    smooth: int = 5
    tolerance: float = 1e-6
    interpolation: Interpolation = "linear"
    substeps: int | Literal["auto"] = "auto"


def run(spec: Any, settings: ValidateSettings, *, progress: Progress | None = None) -> ValidationResult:
    """Validate *settings.fmu*; *progress* is not called (the runs are reported when they end)."""
    fields = {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings) if f.name != "fmu"}
    return validate(spec, settings.fmu, **fields)
