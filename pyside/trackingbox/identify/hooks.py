"""What the estimation stage calls: the identifiability check before, the intervals after.

:func:`before_estimate` runs :func:`~trackingbox.identify.analysis.identify` at
the start values only (one sensitivity run, or ``2 n + 1`` runs of central
differences) and logs a warning per parameter group the data cannot tell
apart, before the global search spends its budget. :func:`after_estimate` adds
the intervals (:func:`~trackingbox.identify.intervals.uncertainty`) and that
check to the :class:`~trackingbox.estimation.EstimationResult`.
"""
from __future__ import annotations

import logging
from dataclasses import replace
from typing import Any

from ..errors import TrackingError

log = logging.getLogger(__name__)


def _method(jacobian: str) -> str:
    """The sensitivities identify uses for the estimation's *jacobian* setting."""
    return "fd" if jacobian == "fd" else "exact" if jacobian == "exact" else "auto"


def before_estimate(spec: Any, *, warmup: float | None, jacobian: str = "auto") -> Any:
    """The identifiability at the start values (warnings logged), or None if it could not be taken."""
    from .analysis import identify

    try:
        found = identify(spec, points=0, method=_method(jacobian), warmup=warmup, candidates=False)
    except TrackingError as exc:
        log.info("no identifiability check before the estimation: %s", exc)
        return None
    for message in found.messages():
        log.warning("estimate: %s (see trackingbox identify %s)", message, getattr(spec, "path", "SPEC"))
    return found


def after_estimate(spec: Any, result: Any, before: Any, *, level: float | None, warmup: float | None,
                   jacobian: str = "auto") -> Any:
    """*result* with the identifiability check and, unless *level* is None, the intervals at its estimate."""
    from .intervals import uncertainty

    extra: dict[str, Any] = {}
    if before is not None:
        extra["identifiability"] = before.to_json()
    if level is not None:
        try:
            extra["uncertainty"] = uncertainty(spec, result.parameters, level=level, method=_method(jacobian),
                                               warmup=warmup)
        except TrackingError as exc:
            log.warning("estimate: no confidence intervals: %s", exc)
    return replace(result, **extra) if extra else result
