"""The exception tree of trackingbox.

Every error a user can cause by bad input is a :class:`TrackingError`; the CLI
prints its message (no traceback) and exits non-zero. Messages name the thing
and where it is ("tag 'TI-301' in measurements.csv ...").
"""
from __future__ import annotations

import difflib
from collections.abc import Iterable


class TrackingError(Exception):
    """Base class of every error trackingbox raises on purpose."""


class SpecError(TrackingError, ValueError):
    """A tracking specification (spec.toml) is malformed or inconsistent."""


class DataError(TrackingError, ValueError):
    """Measurement or input data is malformed (missing columns, NaN, time order)."""


class OutputError(TrackingError, ValueError):
    """An output location cannot or must not be written (not writable, under a file, an input)."""


class CompileError(TrackingError, RuntimeError):
    """Modelica source could not be turned into an FMU."""


class UnsupportedConstructError(CompileError):
    """The Modelica source uses a construct the selected backend cannot compile."""


class FMUError(TrackingError, ValueError):
    """An FMU is missing, corrupt, or does not have the variables asked for."""


class SimulationError(TrackingError, RuntimeError):
    """A simulation failed (solver failure, non-finite values)."""


class AssertionFailed(SimulationError):
    """A Modelica ``assert`` of level error failed during a simulation.

    Attributes
    ----------
    message : str
        The assert's message, as written in the model.
    time : float
        The simulation time (s) at which the failure was detected.
    """

    def __init__(self, message: str, time: float, where: str = "") -> None:
        self.message = message
        self.time = float(time)
        super().__init__(f"assert failed{' in ' + where if where else ''} at t = {self.time:g} s: {message}")


class CheckpointError(TrackingError, ValueError):
    """A checkpoint or journal to resume from is unreadable, corrupt, truncated or belongs to another run."""


class StaleCheckpointError(CheckpointError):
    """A journal to resume from was written by another run (its spec, twin or settings differ): sound, but not
    this run's."""


class LiveError(TrackingError, RuntimeError):
    """The online mode cannot connect, authenticate or read its tags (OPC UA)."""


class EstimationError(TrackingError, RuntimeError):
    """Parameter estimation could not run or failed."""


class AnalysisError(TrackingError, RuntimeError):
    """Step tests, RGA or sensitivity analysis could not produce a result."""


def did_you_mean(name: str, candidates: Iterable[str], n: int = 3) -> str:
    """Return ``" (did you mean 'a', 'b'?)"`` for close matches of *name*, or ``""``.

    >>> did_you_mean("khtt", ["kht", "A", "n"])
    " (did you mean 'kht'?)"
    """
    matches = difflib.get_close_matches(name, list(candidates), n=n, cutoff=0.6)
    if not matches:
        return ""
    return " (did you mean " + ", ".join(repr(m) for m in matches) + "?)"


def unknown_name(kind: str, name: str, candidates: Iterable[str], where: str) -> str:
    """Message for an unknown name: ``unknown parameter 'khtt' in spec.toml (did you mean 'kht'?)``."""
    return f"unknown {kind} {name!r} in {where}{did_you_mean(name, candidates)}"
