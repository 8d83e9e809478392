"""The generate stage: the Modelica ``<Twin>Tracking`` package (tracking box and tracked model) from a spec.

``run(spec, GenerateSettings(out_dir=...))`` -> :class:`~trackingbox.generate.generator.GenerateResult`
(the computation: :func:`trackingbox.generate.generator.generate`); compiling the tracked model is
the next step, :func:`trackingbox.generate.generator.compile_generated`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..generate.generator import GenerateResult, compile_generated, generate
from .contract import Progress

__all__ = ["GenerateSettings", "GenerateResult", "compile_generated", "run"]


@dataclass(frozen=True)
class GenerateSettings:
    """Settings of the generate stage: where the package goes, and whether the twin's source is patched."""

    out_dir: Path
    rewrite: bool = False


def run(spec: Any, settings: GenerateSettings, *, progress: Progress | None = None) -> GenerateResult:
    """Write the package; *progress* is not called (writing takes well under a second)."""
    return generate(spec, settings.out_dir, rewrite=settings.rewrite)
