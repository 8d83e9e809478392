"""The track stage: the twin beside the plant data, its parameters moved by the PI controllers.

``run(spec, TrackSettings(out_dir=...), progress=...)`` -> :class:`~trackingbox.tracking.result.TrackingResult`
(the computation: :func:`trackingbox.tracking.runtime.track`, whose keywords are the settings' fields;
it also takes data a stage's settings do not hold: a measurement view, an untracked table, an
inputs twin).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from ..tracking.controllers import Interpolation
from ..tracking.runtime import (
    CARRY_FRACTION,
    ControllerMode,
    TrackingResult,
    Window,
    track,
)
from .contract import Progress


@dataclass(frozen=True)
class TrackSettings:
    """Settings of the track stage (the ``trackingbox track`` options; see :func:`~trackingbox.tracking.runtime.track`)."""

    out_dir: Path
    resume: bool = False
    max_steps: int | None = None
    window: Window = "all"
    untracked: bool = True
    checkpoint_every: int = 200
    recovery_hold: float | None = None
    tolerance: float = 1e-6
    interpolation: Interpolation = "linear"
    substeps: int | Literal["auto"] = "auto"
    carry: float = CARRY_FRACTION
    controllers: ControllerMode = "discrete"
    window_rows: int | None = None


def run(spec: Any, settings: TrackSettings, *, progress: Progress | None = None) -> TrackingResult:
    """Track with *settings*; *progress* gets the rows (stage ``"tracking"``, unit ``"row"``)."""

    def rows(done: int, total: int) -> None:
        assert progress is not None
        progress("tracking", done, total, unit="row")

    return track(spec, **{f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)},
                 progress=None if progress is None else rows)
