"""What a tracking run returns and keeps: :class:`TrackingResult` and its parts, the running
statistics and fits summarised into it, and the JSON helpers of its checkpoints.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    pass

log = logging.getLogger(__name__)



#: Output files written into ``out_dir``.
CSV_NAME = "tracking.csv"
CHECKPOINT_NAME = "checkpoint.json"
RESULT_NAME = "result.json"


# --------------------------------------------------------------------------- results

@dataclass(frozen=True)
class VariableResult:
    """Fit of one tracking variable over the metric window (after the start-up hold).

    NRMSE = RMSE / range of the measurement (same definition as
    :func:`trackingbox.estimation.nrmse`), over samples where the measurement
    is valid and not inside a stoppage.
    """

    nrmse_untracked: float
    nrmse_tracked: float
    samples: int


@dataclass(frozen=True)
class ParameterResult:
    """Trajectory summary of one tracking parameter (or correction flow) over the run."""

    final: float
    min: float
    max: float
    lower: float
    upper: float


@dataclass(frozen=True)
class TrackingEvent:
    """Something the runtime did on its own: a hold, a recovery, a cold start."""

    time: float
    kind: str
    message: str


@dataclass(frozen=True)
class TrackingResult:
    """Outcome of :func:`track`.

    Attributes
    ----------
    csv : Path
        The streamed trajectory file.
    window : tuple of float
        ``[start, stop)`` (s from the first sample) the metrics were taken over.
    variables : dict
        Tag -> :class:`VariableResult`.
    parameters : dict
        Parameter name -> :class:`ParameterResult`.
    corrections : dict
        State-compensation input -> :class:`ParameterResult` (kg/s; bounds NaN).
    states : dict
        State tag -> :class:`ParameterResult` of the tracked twin's simulated
        level (final/min/max over the run; bounds NaN), to check that no tank
        empties or overflows.
    seconds : float
        Wall-clock seconds of the run (this call).
    seconds_untracked : float
        Wall-clock seconds spent stepping the untracked twin (a plain simulation
        over the same period with the same step), for overhead figures.
    simulated_seconds : float
        Simulated time covered by this call.
    steps : int
        Rows written (total, including rows from before a resume).
    complete : bool
        False when ``max_steps`` stopped the run early (resume to continue).
    events : tuple of TrackingEvent
    restarts, carried : int
        Changes of the tracked twin's parameters and corrections over the run
        (resumed parts included) that re-initialised its integrator, and
        changes it carried (see ``carry`` in :func:`track`).
    """

    csv: Path
    window: tuple[float, float]
    variables: dict[str, VariableResult]
    parameters: dict[str, ParameterResult]
    corrections: dict[str, ParameterResult]
    states: dict[str, ParameterResult]
    seconds: float
    seconds_untracked: float
    simulated_seconds: float
    steps: int
    complete: bool
    events: tuple[TrackingEvent, ...] = ()
    restarts: int = 0
    carried: int = 0

    def to_json(self) -> dict[str, Any]:
        """The ``--json`` document of ``trackingbox track``."""
        return {
            "variables": {t: {"nrmse_untracked": num(v.nrmse_untracked), "nrmse_tracked": num(v.nrmse_tracked)}
                          for t, v in self.variables.items()},
            "parameters": {n: {"final": num(p.final), "min": num(p.min), "max": num(p.max)}
                           for n, p in self.parameters.items()},
            "seconds": self.seconds,
        }


def num(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


# --------------------------------------------------------------------------- helpers

class Stats:
    """Streaming final/min/max of one signal."""

    def __init__(self) -> None:
        self.final = math.nan
        self.min = math.inf
        self.max = -math.inf

    def add(self, x: float) -> None:
        if math.isfinite(x):
            self.final = x
            if x < self.min:  # min() and max() as comparisons: called per sample and signal
                self.min = x
            if x > self.max:
                self.max = x

    def state(self) -> list[float]:
        return [self.final, self.min, self.max]

    def restore(self, s: Sequence[float]) -> None:
        self.final, self.min, self.max = (float(v) for v in s)


class Fit:
    """Streaming NRMSE accumulators for one tag (tracked and untracked on the same samples)."""

    def __init__(self) -> None:
        self.n = 0
        self.sse_t = 0.0
        self.sse_u = 0.0
        self.n_u = 0
        self.sum = 0.0
        self.lo = math.inf
        self.hi = -math.inf

    def add(self, meas: float, tracked: float, untracked: float) -> None:
        if not (math.isfinite(meas) and math.isfinite(tracked)):
            return
        self.n += 1
        self.sse_t += (tracked - meas) ** 2
        if math.isfinite(untracked):
            self.n_u += 1
            self.sse_u += (untracked - meas) ** 2
        self.sum += meas
        if meas < self.lo:
            self.lo = meas
        if meas > self.hi:
            self.hi = meas

    def _scale(self) -> float:
        span = self.hi - self.lo
        return span if span > 0.0 else max(abs(self.sum / self.n), 1.0)

    def result(self) -> VariableResult:
        if self.n == 0:
            return VariableResult(math.nan, math.nan, 0)
        s = self._scale()
        tracked = math.sqrt(self.sse_t / self.n) / s
        untracked = math.sqrt(self.sse_u / self.n_u) / s if self.n_u == self.n else math.nan
        return VariableResult(untracked, tracked, self.n)

    def state(self) -> list[float]:
        return [self.n, self.sse_t, self.sse_u, self.n_u, self.sum, self.lo, self.hi]

    def restore(self, s: Sequence[float]) -> None:
        self.n, self.sse_t, self.sse_u, self.n_u, self.sum, self.lo, self.hi = s
        self.n, self.n_u = int(self.n), int(self.n_u)




def json_float(x: float | None) -> Any:
    if x is None:
        return None
    return x if math.isfinite(x) else repr(float(x))


def from_json_float(x: Any) -> float | None:
    if x is None:
        return None
    return float(x)


def jsonify(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: jsonify(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonify(v) for v in obj]
    if isinstance(obj, float):
        return json_float(obj)
    return obj


def unjsonify(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: unjsonify(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [unjsonify(v) for v in obj]
    if isinstance(obj, str) and obj in ("nan", "inf", "-inf"):
        return float(obj)
    return obj
