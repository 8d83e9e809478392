"""Judge the candidates on held-out data and give the verdict.

A candidate *passes* when all of these hold:

* ``delta_bic > MIN_DELTA_BIC`` (10) on the training window;
* on the validation window its affected tags' mean square residual falls by
  more than noise allows: ``noise_gain > max(MIN_NOISE_GAIN, 4 * sqrt(2 / n))``
  noise variances (``n``: validation samples per tag; the second term is four
  standard deviations of the change a mean square of ``n`` white-noise samples
  shows by chance), and its NRMSE falls by at least :data:`MIN_VALIDATION_GAIN`
  (10 %, mean over the tags it materially moves, :func:`~trackingbox.diagnose.screen.score`); a sensor
  effect must pass that gain on its own tag, and no tag may get worse by more
  than the same margin;
* it explains a gap step 1 found: a sensor effect's tag, or one of the tags a
  process effect changes, is significant (:attr:`WhereResult.significant`);
* it closes every gap it touches: each significant tag the candidate *materially*
  moves (its training residual changed by more than
  :data:`~trackingbox.diagnose.candidates.MATERIAL_MOVE` noise sigmas RMS) gains
  beyond noise on validation (the same threshold). An effect that reshapes a
  significant residual without closing it has the wrong form for that gap, and its
  gain on another tag is a coincidence of fit, not an explanation. On the evaporator
  whose steam chest is blanketed by air after each restart (``bench evaporator
  --hidden ncg-after-restart``, outside the library; 24 h, seed 0) the effect level
  transmitter's density ratio (``level-density@LT_body``, ΔBIC 137) closed the level
  controller output ZI-6150's gap but moved the pump pressure PI-6152's without
  closing it (0.149 noise variances): named before this rule, now ``unexplained``. A
  tag the candidate moves less than that is not held to it: a second effect may be
  behind its gap;
* no fitted parameter is pinned at a bound.

"Noise" is each tag's sensor noise and the spread the inputs' noise causes in the
simulated output, in quadrature (:func:`~trackingbox.diagnose.residuals.propagated_noise`).

Verdict: ``effect`` when a candidate passes. One is named: among the passing
candidates that the training data do not strongly separate from the best-ranked
one (their BIC difference, computed between the two candidates' own residuals
by :func:`~trackingbox.diagnose.screen.delta_bic`, is within :data:`MIN_DELTA_BIC`),
the one with the largest validation gain in noise
variances (the held-out data decide); ``unexplained`` when none passes but the null model's residual is
significant somewhere (the tags and periods are said); ``none`` otherwise. A
candidate that does not pass is never named.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from .candidates import MATERIAL_MOVE, Candidate, delta_bic

if TYPE_CHECKING:
    from .residuals import WhereResult

Verdict = Literal["effect", "none", "unexplained"]

#: ΔBIC a candidate must exceed (strong evidence on Kass and Raftery's scale).
MIN_DELTA_BIC = 10.0
#: Smallest validation gain in noise variances a candidate must show, whatever the sample count.
MIN_NOISE_GAIN = 0.25
#: Smallest relative fall of the affected tags' validation NRMSE (mean over the tags) worth naming an
#: effect for: a statistically clear but practically negligible gain (a 4 % fall on the plain
#: heat-production bench) is no missing effect.
MIN_VALIDATION_GAIN = 0.10


def noise_threshold(samples: int) -> float:
    """Validation gain (noise variances) beyond what noise allows with *samples* per tag.

    >>> round(noise_threshold(720), 3)
    0.25
    >>> round(noise_threshold(50), 3)
    0.8
    """
    return max(MIN_NOISE_GAIN, 4.0 * math.sqrt(2.0 / max(samples, 1)))


def reasons_against(c: Candidate, samples: int) -> list[str]:
    """Why *c* does not pass (empty when it passes)."""
    out = []
    if c.stage == "skipped":
        return [c.reason or "not screened"]
    if not (math.isfinite(c.delta_bic) and c.delta_bic > MIN_DELTA_BIC):
        out.append(f"delta BIC {c.delta_bic:.3g} is not above {MIN_DELTA_BIC:g}")
    limit = noise_threshold(samples)
    if not (math.isfinite(c.noise_gain) and c.noise_gain > limit):
        out.append(f"validation gain {c.noise_gain:.3g} noise variances is not above {limit:.3g}")
    if not (math.isfinite(c.validation_gain) and c.validation_gain > 0):
        out.append("validation NRMSE does not fall")
    elif c.validation_gain < MIN_VALIDATION_GAIN:
        out.append(f"validation NRMSE falls by {100 * c.validation_gain:.1f} %, less than "
                   f"{100 * MIN_VALIDATION_GAIN:g} %")
    if c.kind == "sensor" and c.noise_gains and not c.noise_gains.get(c.target, -math.inf) > limit:
        out.append(f"the validation gain on its own tag {c.target} "
                   f"({c.noise_gains.get(c.target, math.nan):.3g} noise variances) is not above {limit:.3g}")
    worse = [t for t, g in c.noise_gains.items() if g < -limit]
    if worse:
        out.append(f"makes {', '.join(worse)} worse on validation beyond noise")
    if c.pinned:
        out.append(f"pinned at a bound: {', '.join(c.pinned)}")
    return out


@dataclass(frozen=True)
class Judgement:
    """The verdict and what supports it.

    Attributes
    ----------
    verdict
        ``"effect"``, ``"none"`` or ``"unexplained"``.
    named
        The passing candidate named (``effect`` only).
    reasons
        Candidate ``effect@target`` -> why it did not pass.
    unexplained
        Tag -> periods ``(start, stop)`` s where a significant residual remains unexplained.
    """

    verdict: Verdict
    named: Candidate | None
    reasons: dict[str, list[str]]
    unexplained: dict[str, list[tuple[float, float]]]


def between(a: Candidate, b: Candidate) -> float:
    """BIC evidence for *a* over *b* on training, from their own residuals (tags both have).

    Falls back to the difference of their ΔBIC over the null when either lacks residuals.
    """
    tags = [t for t in a.training_residual if t in b.training_residual]
    if not tags:
        return a.delta_bic - b.delta_bic
    return delta_bic({t: b.training_residual[t] for t in tags}, {t: a.training_residual[t] for t in tags}, 0)


def validation_samples(where: WhereResult) -> int:
    """Validation samples per tag the noise threshold counts with (the fewest of any tag)."""
    return min((res.samples for res in where.validation_tags.values()), default=0)


def objections(c: Candidate, where: WhereResult, samples: int | None = None) -> list[str]:
    """Why *c* cannot be named (empty when it passes): :func:`reasons_against` and the gap it must explain.

    The same test serves a screened candidate (is it worth a fit?) and a fitted one (may it be named?).
    """
    why = reasons_against(c, validation_samples(where) if samples is None else samples)
    if c.stage != "skipped":
        significant = set(where.significant)
        if c.kind == "sensor" and c.target not in significant:
            why.append(f"the residual of its tag {c.target} is within noise (nothing there to explain)")
        elif c.kind != "sensor" and not significant & set(c.tags):
            why.append("none of the tags it changes has a residual beyond noise (nothing there to explain)")
        limit = noise_threshold(validation_samples(where) if samples is None else samples)
        unclosed = [t for t in c.material if t in significant and not c.noise_gains.get(t, -math.inf) > limit]
        if unclosed:
            why.append("it moves the significant residual of " + ", ".join(unclosed)
                       + f" by more than {MATERIAL_MOVE:g} noise sigma but does not close it ("
                       + ", ".join(f"{c.noise_gains.get(t, math.nan):.3g}" for t in unclosed)
                       + f" noise variances, not above {limit:.3g}): not what caused that gap")
    return why


def judge(candidates: Sequence[Candidate], where: WhereResult) -> Judgement:
    """Give the verdict over ranked *candidates* (best first)."""
    samples = validation_samples(where)
    reasons: dict[str, list[str]] = {}
    passing = []
    for c in candidates:
        why = objections(c, where, samples)
        if why:
            reasons[f"{c.effect}@{c.target}"] = why
        else:
            passing.append(c)
    if passing:
        top = max(passing, key=lambda c: c.delta_bic)
        best = top.delta_bic
        contenders = [c for c in passing if c is top or between(top, c) <= MIN_DELTA_BIC]
        named = max(contenders, key=lambda c: (c.noise_gain, c.delta_bic))
        for c in passing:
            if c is named:
                continue
            if c in contenders:
                reasons[f"{c.effect}@{c.target}"] = [
                    f"as likely on training as {named.effect}@{named.target} (BIC difference within "
                    f"{MIN_DELTA_BIC:g}) "
                    f"but a smaller validation gain ({c.noise_gain:.3g} vs {named.noise_gain:.3g} noise variances)"]
            else:
                reasons[f"{c.effect}@{c.target}"] = [f"passes, but the training data favour "
                                                     f"{top.effect}@{top.target} by a BIC difference above "
                                                     f"{MIN_DELTA_BIC:g} (ΔBIC {c.delta_bic:.4g} vs {best:.4g})"]
        return Judgement("effect", named, reasons, {})
    unexplained = {}
    for tag in where.significant:
        periods = list(where.tags[tag].periods) + list(where.validation_tags[tag].periods)
        unexplained[tag] = [(float(a), float(b)) for a, b in periods]
    return Judgement("unexplained" if unexplained else "none", None, reasons, unexplained)
