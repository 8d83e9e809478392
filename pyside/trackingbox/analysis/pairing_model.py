"""What a pairing is: :class:`Pair`, :class:`Pairing`, the data checks' thresholds (:class:`DataChecks`)
and the constants of the rules (:mod:`.pairing` chooses; :mod:`.data_checks` judges with data).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from ..errors import AnalysisError
from .blocks import Block
from .offsets import OffsetStats

logger = logging.getLogger(__name__)


#: Relative gains above this are flagged: the pairing is sensitive to model error.
LARGE_LAMBDA = 10.0
#: Scaled gains below this fraction of the largest scaled gain count as negligible.
NEGLIGIBLE = 1e-3
#: Rank tolerance on the scaled gain matrix: a parameter whose gain column adds less than
#: this fraction of the largest singular value (or whose column is parallel to a stronger one
#: within ``RANK_RTOL`` rad) cannot be told apart from the others and is left out
#: before the RGA. 1e-2 keeps the condition number of what is paired below ~1e2; on the
#: heat-production bench it separates valves from the pipes in series with them.
RANK_RTOL = 1e-2
#: Pairs with a smaller relative gain are not chosen: the loop's effect would depend almost
#: entirely on the other loops (close to zero: the classic "never pair on lambda near 0").
MIN_LAMBDA = 0.1
FORBIDDEN = 1e6
#: With a closed-loop time constant (:attr:`DataChecks.closed_loop`), the predicted ratio counts
#: from this many of them after the window's first sample (95 % settled): tracking is judged on a
#: window after its start-up (the evaporator's validation window), not on its loops' first hours.
SETTLE_LOOPS = 3.0
#: Ratio of consecutive loop time constants :func:`loop_ladder` tries for one pair.
LADDER_STEP = math.sqrt(2.0)
#: The move of an unpaired candidate (a fraction of its bound range) ``max_leak`` is set for: at 0.5
#: a fifth of its range biases a paired parameter by at most a tenth of its own (see
#: :class:`DataChecks`). With pairing per unit the check takes the smaller move the data allow
#: (:meth:`DataView.moved_at_most`) when they bound it below this.
SEPARATION_MOVE = 0.2
#: Pairing per unit: a unit's tag at its noise floor stays a candidate for its own unit's parameter when
#: a move of ``IDENTIFY_MOVE`` of that parameter's bound range (the done-criterion's tolerance, 10 %)
#: shows on it as at least ``IDENTIFY_FLOOR`` times its noise floor (:meth:`DataView.identifies`). On the
#: 7-effect train (48 h, seed 0) the steam-chest pressures the pairing takes for effects 2-6 show their
#: effect's fouling at 10.5-15.6 x their floor, effect 1's liquor flow FI-7150 at 0.32 x, and the last
#: effect's steam chest PI-7721, left out at its floor, at 12.7 x.
IDENTIFY_MOVE = 0.1
IDENTIFY_FLOOR = 5.0


@dataclass(frozen=True)
class DataChecks:
    """Thresholds of the data-aware checks (used when residuals are given).

    Attributes
    ----------
    noise_ratio : float
        A variable whose untracked RMS error is below this many times its
        sensor noise is left out (tracking cannot remove noise: at 5 it could
        at best bring the error down to a fifth).
    min_reach : float
        A pair is allowed only if the parameter's remaining range, in the
        direction that closes the mean offset, moves the variable by at least
        this many times the offset. 0.5: the parameter alone closes at least
        half of it; the rest is judged together with the other loops (which
        also move the variable) by the prediction below.
    max_ratio : float
        Largest predicted tracked/untracked RMS ratio of a chosen pair (see
        :func:`~trackingbox.analysis.offsets.predict_tracking`).
    max_condition : float
        Warn when the scaled gains of the chosen pairs have a larger condition number.
    closed_loop : float
        Shortest closed-loop time constant (s) the prediction gives a loop (0: the
        pair's step-response time constant, the loop ``lambda = 1`` tunes). A loop
        tuned slower than its step response (slow fouling and wear, noise kept out
        of the parameter) follows only the slow part of the error: what changes
        faster, the sensor noise and the historian's held values included, stays
        in the tracked error, and the prediction counts it, from :data:`SETTLE_LOOPS`
        closed-loop time constants after the window's start. With it the checks are
        floor-aware instead of using ``noise_ratio``: a variable whose noise floor (its
        noise, or for a held tag :func:`~trackingbox.analysis.offsets.noise_floor`) is
        more than ``max_floor`` of its untracked RMS error after the loops settled is
        left out (no loop brings it under that), and a pair is judged by what it leaves
        of the error *above* the floor, ``sqrt((r^2 - f^2) / (1 - f^2))`` for the
        predicted ratio ``r`` and the floor's ratio ``f``, against ``max_ratio``.
    max_floor : float
        See *closed_loop*: the tracked/untracked ratio asked for (the issue's 30 %).
    closed_loop_min : float
        Loop speed per pair (0, the default: every loop at *closed_loop*). With it (and
        ``0 < closed_loop_min <= closed_loop``) a pair the prediction finds above ``max_ratio``
        with a loop of *closed_loop* is predicted again with its own loop one step of
        :func:`loop_ladder` faster, down to *closed_loop_min*, before it is refused; the other
        pairs keep theirs. So each pair gets the slowest loop its own tag's error allows (a
        fouling ramp the loop lags by slope x time constant), and every other loop stays as slow
        as *closed_loop* keeps the noise out of its parameter. The start-up skipped and the
        noise floor stay those of *closed_loop*. A floor-aware lower limit: a loop faster than the
        30 min span of :func:`~trackingbox.analysis.offsets.noise_floor` follows part of what the
        floor counts as noise.
    max_leak : float
        Separation (:func:`leakage`): largest steady-state move of a paired parameter, in
        fractions of its bound range, per bound range of a candidate left unpaired. 0.5: an
        unpaired candidate off by a fifth of its range biases the paired parameter by at most a
        tenth of its range; above it the pair's tag tells the other candidate more than its own
        parameter. ``math.inf`` (the default) switches the check off: where candidates are
        inseparable by design (a pipe's loss in series with its valve, heat production) the loop on
        one stands for both, and the check would refuse it. A spec asks for it with
        ``[pairing] max_leak`` (the evaporator train: 0.5).
    max_jitter : float
        Loop noise (with ``closed_loop``): the largest standard deviation, in fractions of its bound
        range, that a pair's loop may put into its parameter from its tag's fast error
        (:func:`~trackingbox.analysis.offsets.loop_jitter` of the untracked error over the gain).
        Once the other checks have chosen the pairs and their loops, a pair whose loop is faster
        than the fastest rung of :func:`loop_ladder` within this limit (the slowest rung if none
        is) is slowed to it: the ladder makes a loop faster to cut its tag's error, and where
        that error is mostly the tag's noise a faster loop buys the tag little and puts the noise
        into the parameter (the evaporator train's effect 1 on its liquor flow FI-7150, whose
        noise floor a tenth of the fouling's range moves by a third: at 30 min the tracked fouling
        swung by 23 % of its range, at 1 h by 15 %, while the tag's tracked/untracked ratio stayed
        0.16 and 0.15). The pair's predicted ratio is then that of its slower loop, and a pair so
        slowed is not refused for it (a warning says so). ``math.inf`` (the default): no limit.
    """

    noise_ratio: float = 5.0
    min_reach: float = 0.5
    max_ratio: float = 0.25
    max_condition: float = 100.0
    closed_loop: float = 0.0
    max_floor: float = 0.3
    max_leak: float = math.inf
    closed_loop_min: float = 0.0
    max_jitter: float = math.inf

    def __post_init__(self) -> None:
        for name in ("noise_ratio", "min_reach", "max_ratio", "max_condition", "closed_loop", "max_floor",
                     "max_leak", "closed_loop_min", "max_jitter"):
            value = getattr(self, name)
            finite = math.isfinite(value) if isinstance(value, (int, float)) else False
            unbounded = name in ("max_leak", "max_jitter")
            if not (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and (finite or (unbounded and value == math.inf)) and value >= 0):
                raise AnalysisError(f"pairing check {name} must be a non-negative number"
                                    f"{' (or inf)' if unbounded else ''}, got {value!r}")
        if not self.max_jitter > 0:
            raise AnalysisError(f"pairing check max_jitter must be > 0, got {self.max_jitter!r}")
        if self.closed_loop_min > 0 and not (self.closed_loop > 0 and self.closed_loop_min <= self.closed_loop):
            raise AnalysisError(f"pairing check closed_loop_min = {self.closed_loop_min:g} s needs a closed_loop at "
                                f"least as long (the slowest loop, tried first), got closed_loop = "
                                f"{self.closed_loop:g} s")

    def ladder(self) -> tuple[float, ...]:
        """The loop time constants a pair may get, slowest first (:func:`loop_ladder`; one, or none
        without *closed_loop*)."""
        if not self.closed_loop > 0:
            return ()
        return loop_ladder(self.closed_loop, self.closed_loop_min or self.closed_loop)


def loop_ladder(slowest: float, fastest: float, step: float = LADDER_STEP) -> tuple[float, ...]:
    """Closed-loop time constants from *slowest* down to *fastest*, each *step* times the next.

    The last one is *fastest* itself (the step before it may be shorter than *step*).

    Examples
    --------
    >>> [round(t) for t in loop_ladder(7200.0, 1800.0)]
    [7200, 5091, 3600, 2546, 1800]
    >>> loop_ladder(3600.0, 3600.0), loop_ladder(3600.0, 3000.0)
    ((3600.0,), (3600.0, 3000.0))
    """
    if not (0 < fastest <= slowest and math.isfinite(slowest) and step > 1):
        raise AnalysisError(f"loop ladder: need 0 < fastest <= slowest and step > 1, got {fastest!r}, "
                            f"{slowest!r}, {step!r}")
    out = [float(slowest)]
    while out[-1] / step > fastest * (1.0 + 1e-9):
        out.append(out[-1] / step)
    if out[-1] > fastest * (1.0 + 1e-9):
        out.append(float(fastest))
    return tuple(out)


@dataclass(frozen=True)
class Pair:
    """One tracking variable driven by one tracking parameter.

    Attributes
    ----------
    variable : str
        Tracking variable (measurement tag or twin output name).
    parameter : str
        Tracking parameter (FMU parameter name).
    lambda_ : float
        Relative gain of the pair.
    gain : float
        Steady-state gain ``d variable / d parameter`` in engineering units.
    time_constant : float
        First-order time constant (s) of the variable's step response to the
        parameter; NaN when unknown.
    predicted_ratio : float
        Expected tracked/untracked RMS ratio (NaN without data checks).
    at_bound : float
        Expected fraction of the time the parameter sits at a bound (NaN without data checks).
    closed_loop : float
        Closed-loop time constant (s) the prediction judged the pair with: the spec's
        ``closed_loop``, or with ``closed_loop_min`` the pair's own (see :class:`DataChecks`);
        NaN without one. :func:`~trackingbox.analysis.pair_stage.spec_pairs` tunes the pair for it.
    rga_from : str
        ``"structure"``: the pair and its relative gain come from the RGA of the
        step tests that set the structure (with a freeze: frozen);
        ``"recording"``: from the RGA of the step tests with nothing frozen, for a
        tag no parameter moves with the freeze (see :func:`complete_with_recording`).
    """

    variable: str
    parameter: str
    lambda_: float
    gain: float
    time_constant: float = math.nan
    predicted_ratio: float = math.nan
    at_bound: float = math.nan
    rga_from: str = "structure"
    closed_loop: float = math.nan


@dataclass(frozen=True)
class Pairing:
    """Result of :func:`choose_pairs`.

    Attributes
    ----------
    pairs : tuple of Pair
        Chosen pairs, in the order of the variables.
    left_out : tuple of (str, str)
        ``(name, reason)`` for every variable and parameter not paired.
    warnings : tuple of str
        Negative or large relative gains, poor conditioning.
    variables, parameters : tuple of str
        Row and column names of the matrices below.
    gains : ndarray, shape (m, n)
        Gain matrix in engineering units.
    scaled_gains : ndarray, shape (m, n)
        Gains scaled by variable and parameter ranges.
    rga : ndarray, shape (m, n)
        Relative gain array of the scaled gains over the variables and
        parameters that took part (NaN elsewhere).
    condition_number : float
        Condition number of the scaled gains that took part.
    offsets : tuple of OffsetStats
        Untracked error and sensor noise per variable (empty without data).
    reach : ndarray, shape (m, n)
        ``|gain| x remaining range / |offset|`` per pair (NaN without data).
    checks : DataChecks or None
        Thresholds used (None without data).
    pairs_condition_number : float
        Condition number of the scaled gains of the chosen pairs.
    rejected : tuple of (variable, parameter, reason)
        Pairs the tracking prediction forbade, in the order they were tried.
    block : Block or None
        With ``units``: the unit parameters' pairs on their own tags and the relative gain array
        of that square block (:func:`~trackingbox.analysis.blocks.choose_block`), the pairs'
        ``lambda_`` taken from it.
    """

    pairs: tuple[Pair, ...]
    left_out: tuple[tuple[str, str], ...]
    warnings: tuple[str, ...]
    variables: tuple[str, ...] = ()
    parameters: tuple[str, ...] = ()
    gains: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False, repr=False)
    scaled_gains: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False, repr=False)
    rga: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False, repr=False)
    condition_number: float = math.nan
    offsets: tuple[OffsetStats, ...] = ()
    reach: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False, repr=False)
    checks: DataChecks | None = None
    pairs_condition_number: float = math.nan
    rejected: tuple[tuple[str, str, str], ...] = ()
    block: Block | None = field(default=None, compare=False)

    def parameter_for(self, variable: str) -> str | None:
        """The parameter paired with *variable*, or None."""
        for p in self.pairs:
            if p.variable == variable:
                return p.parameter
        return None


def fmt(x: float) -> str:
    return f"{x:.3g}"


def recording_time_constants(structure: npt.ArrayLike, recording: npt.ArrayLike) -> np.ndarray:
    """Time constants of the twin as recorded where measured, else those of the structure step tests.

    Examples
    --------
    >>> recording_time_constants([[10.0, 20.0]], [[30.0, float("nan")]]).tolist()
    [[30.0, 20.0]]
    """
    a = np.asarray(structure, dtype=float)
    b = np.asarray(recording, dtype=float)
    return np.where(np.isfinite(b) & (b > 0), b, a)


def replace_ratio(p: Pair, figures: tuple[float, float] | None) -> Pair:
    """*p* with the predicted ratio and time at a bound *figures* (unchanged when None)."""
    if figures is None:
        return p
    return replace(p, predicted_ratio=float(figures[0]), at_bound=float(figures[1]))
