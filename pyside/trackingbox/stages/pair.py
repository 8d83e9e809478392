"""The pair stage: step tests, RGA (and/or Sobol) and data checks choose one tracking parameter per tag.

``run(spec, PairSettings(...), progress=...)`` -> :class:`~trackingbox.analysis.pair_stage.PairingResult`
(the computation: :func:`trackingbox.analysis.pair_stage.pair`). Writing the pairs back into the
spec is the caller's step: ``spec.write_pairs(path, spec_pairs(spec, result))``.
"""
from __future__ import annotations

from typing import Any

from ..analysis.pair_stage import PairingResult, PairSettings, pair, spec_pairs
from .contract import Progress

__all__ = ["PairSettings", "PairingResult", "run", "spec_pairs"]


def run(spec: Any, settings: PairSettings = PairSettings(), *, progress: Progress | None = None) -> PairingResult:
    """Choose the pairs with *settings*; *progress* gets ``(stage, done, total)`` of each phase."""
    return pair(spec, settings, progress=progress)
