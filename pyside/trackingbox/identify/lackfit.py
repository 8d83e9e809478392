"""Whether the twin fits the data at the estimate: the condition the confidence intervals rest on.

The intervals of :mod:`.intervals` measure how far the data let an estimate move *if the twin's
structure is right*: the residuals' noise and autocorrelation make them wider, but an effect the
twin lacks makes them wrong, not wider. It biases the estimate (the parameters take up what they
can of the missing effect: on the single evaporator's own plant, whose twin lacks its vent, heat
losses and DS meter's bias, the boiling-point-rise factor's 95 % interval was [0.931, 0.964]
against a truth of 1.0) and no interval drawn from the residuals' spread holds that bias. What the data can say is whether the twin disagrees with them beyond their noise.

That is diagnose's test (:func:`trackingbox.diagnose.residuals.where`), here run at the estimate:
each output tag's residual on the training and the validation window against the noise its sensor
and its inputs account for (the twin re-run on a second draw of the inputs' noise), after the
small linear polish diagnose gives its null model. A tag beyond its noise (its RMS above 1.5 noise
standard deviations, its mean or its trend over the window above one) is *lack of fit*: the
intervals are then conditional on a structure the data contradict, and the estimate says so and
points at ``trackingbox diagnose``. It does not widen the intervals: how far the bias reaches is
what the missing effect decides, which the residuals do not name.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

from ..errors import TrackingError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TagMisfit:
    """One tag the twin disagrees with beyond its noise at the estimate.

    ``rms`` and ``offset`` are in units of the tag's noise standard deviation (``noise``, tag units),
    on the training and the validation window.
    """

    tag: str
    noise: float
    rms: tuple[float, float]
    offset: tuple[float, float]

    def text(self) -> str:
        return (f"{self.tag} (RMS {self.rms[0]:.2g}/{self.rms[1]:.2g}, mean {self.offset[0]:+.2g}/"
                f"{self.offset[1]:+.2g} noise sigmas on training/validation)")

    def to_json(self) -> dict[str, Any]:
        return {"noise": _num(self.noise), "rms": {"training": _num(self.rms[0]), "validation": _num(self.rms[1])},
                "offset": {"training": _num(self.offset[0]), "validation": _num(self.offset[1])}}


@dataclass(frozen=True)
class LackOfFit:
    """The tags the twin disagrees with beyond their noise at the estimate (empty: none), or why not checked."""

    checked: bool
    tags: tuple[TagMisfit, ...] = ()
    note: str = ""

    @property
    def found(self) -> bool:
        return bool(self.tags)

    def message(self, spec_path: Any = "SPEC") -> str:
        """One line for the estimate's output (empty where the twin fits within the noise)."""
        if not self.checked:
            return f"lack of fit not checked: {self.note}"
        if not self.tags:
            return ""
        return ("lack of fit: the twin disagrees with " + ", ".join(t.text() for t in self.tags)
                + " beyond their noise at the estimate; the intervals hold only if its structure is right, and "
                f"an effect it lacks biases the estimates beyond them (trackingbox diagnose {spec_path})")

    def to_json(self) -> dict[str, Any]:
        return {"checked": self.checked, "tags": {t.tag: t.to_json() for t in self.tags}, "note": self.note,
                "test": "diagnose's residual test (trackingbox.diagnose.residuals.where) at the estimate"}


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def lack_of_fit(spec: Any, result: Any, *, warmup: float | None = None) -> LackOfFit:
    """Diagnose's residual test at *result*'s estimate (an :class:`~trackingbox.estimation.EstimationResult`)."""
    from ..diagnose.residuals import where

    try:
        found = where(spec, null=result, estimate_options={} if warmup is None else {"warmup": warmup})
    except TrackingError as exc:
        log.warning("estimate: the fit at the estimate was not checked against the noise: %s", exc)
        return LackOfFit(False, note=str(exc))
    tags = []
    for tag in found.significant:
        tr, va = found.tags[tag], found.validation_tags[tag]
        sigma = tr.noise
        if not sigma > 0:
            continue
        tags.append(TagMisfit(tag, sigma, (tr.rms / sigma, va.rms / sigma), (tr.offset / sigma, va.offset / sigma)))
    return LackOfFit(True, tuple(tags))
