"""What the stages call: the identifiability check and the intervals around the estimation, pairing's
candidate check, the tracking run's bands.

:func:`before_estimate` runs :func:`~trackingbox.identify.analysis.identify` at
the start values and one point inside the bounds (two sensitivity runs, or
``2 (2 n + 1)`` runs of central differences: a second point tells a product's
structure from a direction that only happens to look like one) and logs a
warning per parameter group the data cannot tell apart, before the global
search spends its budget. :func:`after_estimate` adds the intervals
(:func:`~trackingbox.identify.intervals.uncertainty`), whether the twin fits the data within their
noise at the estimate (:func:`~trackingbox.identify.lackfit.lack_of_fit`: the intervals' condition)
and that check to the
:class:`~trackingbox.estimation.EstimationResult` (the estimate stage calls
both). :func:`indistinct_candidates` is pairing's check, :func:`band_tracker`
the tracking loop's bands (with their fixed part, :mod:`.held`).
"""
from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

import numpy as np

from ..errors import TrackingError
from .analysis import identify, leave_out
from .bands import BandTracker
from .held import band_parts
from .intervals import uncertainty
from .lackfit import lack_of_fit

log = logging.getLogger(__name__)


def _method(jacobian: str) -> str:
    """The sensitivities identify uses for the estimation's *jacobian* setting."""
    return "fd" if jacobian == "fd" else "exact" if jacobian == "exact" else "auto"


def before_estimate(spec: Any, *, warmup: float | None, jacobian: str = "auto", progress: Any = None) -> Any:
    """The identifiability at the start values (warnings logged), or None if it could not be taken
    (*progress*: ``progress(stage, done, total)`` per sensitivity point)."""
    try:
        found = identify(spec, points=1, method=_method(jacobian), warmup=warmup, candidates=False,
                         progress=progress)
    except TrackingError as exc:
        log.info("no identifiability check before the estimation: %s", exc)
        return None
    for message in found.messages():
        log.warning("estimate: %s (see trackingbox identify %s)", message, getattr(spec, "path", "SPEC"))
    return found


def after_estimate(spec: Any, result: Any, before: Any, *, level: float | None, warmup: float | None,
                   jacobian: str = "auto", progress: Any = None) -> Any:
    """*result* with the identifiability check and, unless *level* is None, the intervals at its estimate
    (*progress*: ``progress(runs, budget)`` per twin run of the profiles)."""
    extra: dict[str, Any] = {}
    if before is not None:
        extra["identifiability"] = before.to_json()
    if level is not None:
        try:
            unc = uncertainty(spec, result.parameters, level=level, method=_method(jacobian), warmup=warmup,
                              progress=progress)
        except TrackingError as exc:
            log.warning("estimate: no confidence intervals: %s", exc)
        else:
            misfit = lack_of_fit(spec, result, warmup=warmup)
            if misfit.found:
                log.warning("estimate: %s", misfit.message(getattr(spec, "path", "SPEC")))
            extra["uncertainty"] = replace(unc, lack_of_fit=misfit)
    return replace(result, **extra) if extra else result


def band_tracker(spec: Any, columns: Any) -> Any:
    """The :class:`~trackingbox.identify.bands.BandTracker` of a tracking run (None without pairs), with the
    fixed part of the parameters the twin holds at an estimate with an interval, with several pairs the
    loops' gain matrix, and the untracked tags' closed-loop gains (:func:`~trackingbox.identify.held.band_parts`:
    step tests on the twin, none with one pair, every output paired and no such parameter)."""
    if not getattr(spec, "pairs", None):
        return None
    fixed, note, gains, misfit = band_parts(spec)
    return BandTracker(spec, columns, fixed=fixed or None, note=note, gains=gains, misfit=misfit)


def indistinct_candidates(spec: Any, *, warmup: float | None = None, progress: Any = None) -> dict[str, str]:
    """Pairing's candidates the data cannot tell apart: name -> the reason to leave it out.

    :func:`~trackingbox.identify.analysis.identify` at the start values and one point inside the
    bounds, then :func:`~trackingbox.identify.analysis.leave_out`. Nothing (and a log line) when
    the check cannot run (the twin fails at the start values, a window with too few samples).
    *progress*: ``progress(stage, done, total)`` per sensitivity point.
    """
    try:
        found = identify(spec, points=1, warmup=warmup, candidates=False, progress=progress)
    except TrackingError as exc:
        log.info("pairing without the identifiability check: %s", exc)
        return {}
    drop = leave_out(found)
    for name, why in drop.items():
        log.info("pairing leaves out %s: %s", name, why)
    return drop


def without_candidates(steptest: Any, drop: Any) -> Any:
    """*steptest* (a :class:`~trackingbox.analysis.steptest.StepTestResult` or None) with the gains of the
    candidates in *drop* set to zero, so that the assignment cannot choose them."""
    if steptest is None or not drop:
        return steptest
    cols = [j for j, p in enumerate(steptest.parameters) if p in drop]
    masked = {}
    for name in ("gains", "gains_up", "gains_down"):
        g = np.array(getattr(steptest, name), dtype=float, copy=True)
        g[:, cols] = 0.0
        masked[name] = g
    return replace(steptest, **masked)


def explain(left_out: Any, drop: Any) -> tuple[tuple[str, str], ...]:
    """The pairing's left-out list with the identifiability reason for the candidates in *drop*."""
    return tuple((name, drop.get(name, why)) for name, why in left_out)
