"""Choose one tracking parameter per tracking variable from a steady-state gain matrix.

The relative gain array of the (scaled) gain matrix decides: each variable gets
the unused parameter whose relative gain is positive and closest to one, solved
as an assignment problem so that no parameter is used twice. Every variable and
parameter left out gets a reason.

With data (``residuals``: the untracked twin beside the measurements, see
:mod:`.offsets`) the pairing also asks whether tracking can *use* a pair:

1. a variable whose untracked error is within ``noise_ratio`` x its sensor
   noise has nothing to track and is left out;
2. a pair whose parameter cannot close the variable's mean offset from inside
   its bounds (``|gain| x remaining range < min_reach x |offset|``) is not
   allowed; a variable no parameter can serve is left out before the RGA;
3. the chosen set is checked with :func:`.offsets.predict_tracking` (all loops
   together, parameters clipped to their bounds, first-order loops): while a
   pair would leave more than ``max_ratio`` of its variable's untracked error
   (a parameter pushed to its bound by the other loops, or an error faster than
   the loop), the worst such pair is forbidden and the assignment redone;
4. the chosen set is checked for separation (:func:`leakage`): a paired
   parameter must be told apart from every candidate left unpaired. At steady
   state the loops move their parameters by ``-S_pp^-1 S_pu`` times the moves of
   the unpaired candidates (scaled gains: bound ranges per bound range); while a
   paired parameter would move by more than ``max_leak`` of its range per range
   of an unpaired candidate (its tag follows that candidate rather than its own
   parameter: its trajectory would show the other's degradation), the worst such
   pair is forbidden and the assignment redone, so the parameter goes to a tag
   that identifies it apart from the others, or stays unpaired with that reason.

With a closed-loop time constant (``closed_loop``) every loop is predicted that slow; with
``closed_loop_min`` as well, each pair gets its own loop speed: a pair whose prediction at
``closed_loop`` leaves more than ``max_ratio`` is predicted again with its own loop faster
(:func:`loop_ladder`: steps of sqrt 2 down to ``closed_loop_min``) before it is refused, so
each pair keeps the slowest loop its own error allows (:attr:`Pair.closed_loop`).

With ``units`` (pairing per unit, :mod:`.blocks`; the spec's ``[pairing] units``) the parameters of
indexed units (an evaporator train's ``effect[k].Rf``) pair only with their own unit's tags, chosen
on the relative gain array of the square block they form rather than on the whole tall matrix's
(which a chain of effects makes ill-conditioned); the separation check then runs before the
prediction, and it takes the move the data allow a candidate left unpaired
(:meth:`_DataView.leak_weights`).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from ..errors import AnalysisError
from .blocks import Block, choose_block, square_rga
from .offsets import OffsetStats, Residuals, loop_jitter, predict_tracking, reach
from .rga import _greedy_independent, condition_number, relative_gain_array, scale_gains

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
_FORBIDDEN = 1e6
#: With a closed-loop time constant (:attr:`DataChecks.closed_loop`), the predicted ratio counts
#: from this many of them after the window's first sample (95 % settled): tracking is judged on a
#: window after its start-up (the evaporator's validation window), not on its loops' first hours.
SETTLE_LOOPS = 3.0
#: Ratio of consecutive loop time constants :func:`loop_ladder` tries for one pair.
LADDER_STEP = math.sqrt(2.0)
#: The move of an unpaired candidate (a fraction of its bound range) ``max_leak`` is set for: at 0.5
#: a fifth of its range biases a paired parameter by at most a tenth of its own (see
#: :class:`DataChecks`). With pairing per unit the check takes the smaller move the data allow
#: (:meth:`_DataView.moved_at_most`) when they bound it below this.
SEPARATION_MOVE = 0.2
#: Pairing per unit: a unit's tag at its noise floor stays a candidate for its own unit's parameter when
#: a move of ``IDENTIFY_MOVE`` of that parameter's bound range (the done-criterion's tolerance, 10 %)
#: shows on it as at least ``IDENTIFY_FLOOR`` times its noise floor (:meth:`_DataView.identifies`). On the
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


def _fmt(x: float) -> str:
    return f"{x:.3g}"


def choose_pairs(gains: npt.ArrayLike, variables: Sequence[str], parameters: Sequence[str], *,
                 time_constants: npt.ArrayLike | None = None,
                 variable_ranges: npt.ArrayLike | None = None,
                 parameter_ranges: npt.ArrayLike | None = None,
                 negligible: float = NEGLIGIBLE, large: float = LARGE_LAMBDA,
                 rtol: float = RANK_RTOL, residuals: Residuals | None = None,
                 bounds: npt.ArrayLike | None = None, checks: DataChecks | None = None,
                 other_gains: npt.ArrayLike | None = None, other_time_constants: npt.ArrayLike | None = None,
                 min_lambda: float = MIN_LAMBDA, check_gains: npt.ArrayLike | None = None,
                 check_time_constants: npt.ArrayLike | None = None,
                 units: tuple[Sequence[int | None], Sequence[int | None]] | None = None) -> Pairing:
    """Pair tracking variables with tracking parameters by relative gain.

    Steps: scale the gains (``scale_gains``); leave out parameters and
    variables whose largest scaled gain is below ``negligible`` times the
    largest in the matrix; leave out parameters whose gain column is a linear
    combination of stronger ones (the RGA would be undefined); compute the RGA
    of what remains; assign with :func:`scipy.optimize.linear_sum_assignment`
    on the cost ``|λ - 1|``, negative and zero ``λ`` forbidden.

    Parameters
    ----------
    gains : array_like, shape (m, n)
        ``g_ij = dy_i / dp_j`` in engineering units.
    variables : sequence of str, length m
    parameters : sequence of str, length n
    time_constants : array_like, shape (m, n), optional
        Step-response time constants (s), copied into the chosen pairs.
    variable_ranges, parameter_ranges : array_like, optional
        Scaling ranges (see :func:`~trackingbox.analysis.rga.scale_gains`).
    negligible : float
        Relative threshold for negligible gains.
    large : float
        Relative gains above this are flagged.
    rtol : float
        Rank tolerance on the scaled gains.
    residuals : Residuals, optional
        Measured and untracked simulated series of the variables
        (:func:`~trackingbox.analysis.offsets.simulate_untracked`); turns on the
        data checks (noise level, reach, predicted tracking; see the module notes).
        Variables without samples there are not checked.
    bounds : array_like, shape (n, 3), optional
        ``(start, min, max)`` of each parameter; required with *residuals*.
    checks : DataChecks, optional
        Thresholds of the data checks (defaults: :class:`DataChecks`).
    other_gains, other_time_constants : array_like, shape (m, n), optional
        Gains and time constants from step tests at a second operating point.
        A pair whose gain changes sign between the points is not chosen; a
        chosen pair takes the gain of larger magnitude (and its time constant):
        tuned for the highest gain seen, the loop stays stable where the gain grows.
    min_lambda : float
        Smallest relative gain a chosen pair may have.
    check_gains, check_time_constants : array_like, shape (m, n), optional
        Gains and time constants of the twin run the way the data were recorded
        (e.g. its controllers active while *gains* come from step tests with
        them frozen; see :mod:`~trackingbox.analysis.pair_stage`). When given, the data checks
        (reach, predicted tracking) use these instead of *gains*, the RGA keeps
        *gains*; a pair whose two gains differ in sign is not chosen, and a
        chosen pair's gain is the larger in magnitude of all the gain sets
        (the tracking loop runs on the twin as recorded, and tuned for the
        highest gain seen it stays stable where the gain grows).
    units : (sequence of int or None, sequence of int or None), optional
        Pairing per unit (:mod:`~trackingbox.analysis.blocks`): the unit index of each variable
        and of each parameter (None: not a unit's). A parameter of unit ``k`` pairs only with a
        variable of unit ``k``, one per parameter, chosen so that the square relative gain array
        of those parameters and variables is closest to the identity
        (:func:`~trackingbox.analysis.blocks.choose_block`), each pair's relative gain there at
        least *min_lambda*; the other parameters pair on the relative gains of the whole matrix
        over the variables the block leaves, the most pairs in all first. The data checks apply
        to every pair as before.

    Returns
    -------
    Pairing

    Raises
    ------
    AnalysisError
        If names and matrix shapes disagree.

    Examples
    --------
    >>> p = choose_pairs([[2.0, 0.1], [0.2, 1.0]], ["T1", "T2"], ["a", "b"])
    >>> [(x.variable, x.parameter) for x in p.pairs]
    [('T1', 'a'), ('T2', 'b')]
    """
    G = np.asarray(gains, dtype=float)
    variables = tuple(str(v) for v in variables)
    parameters = tuple(str(p) for p in parameters)
    if G.shape != (len(variables), len(parameters)):
        raise AnalysisError(f"gain matrix has shape {G.shape} but there are {len(variables)} variables "
                            f"and {len(parameters)} parameters")
    m, n = G.shape
    if time_constants is None:
        tau = np.full((m, n), math.nan)
    else:
        tau = np.asarray(time_constants, dtype=float)
        if tau.shape != G.shape:
            raise AnalysisError(f"time-constant matrix has shape {tau.shape}, gains have {G.shape}")
    bad = np.argwhere(~np.isfinite(G))
    if bad.size:
        i, j = bad[0]
        raise AnalysisError(f"gain of {variables[i]!r} to {parameters[j]!r} is not finite ({G[i, j]})")
    S = scale_gains(G, variable_ranges, parameter_ranges)

    left_out: list[tuple[str, str]] = []
    warnings: list[str] = []
    absS = np.abs(S)
    top = float(absS.max()) if absS.size else 0.0
    if top == 0.0:
        for v in variables:
            left_out.append((v, "no candidate parameter changes it (all gains are zero)"))
        for p in parameters:
            left_out.append((p, "changes no tracking variable (all gains are zero)"))
        return Pairing((), tuple(left_out), ("gain matrix is all zeros",), variables, parameters,
                       G, S, np.full((m, n), math.nan), math.inf)

    floor = negligible * top
    col_ok = absS.max(axis=0) >= floor
    row_ok = absS.max(axis=1) >= negligible * top
    for j in np.flatnonzero(~col_ok):
        left_out.append((parameters[j], f"negligible gain: its largest scaled gain {_fmt(absS[:, j].max())} "
                                        f"is below {negligible:g} x the largest in the matrix ({_fmt(top)})"))
    for i in np.flatnonzero(~row_ok):
        left_out.append((variables[i], f"no candidate parameter moves it: largest scaled gain "
                                       f"{_fmt(absS[i].max())} is below {negligible:g} x {_fmt(top)}"))
    rows = [int(i) for i in np.flatnonzero(row_ok)]
    cols = [int(j) for j in np.flatnonzero(col_ok)]

    # parallel columns: two parameters with the same effect direction cannot be told apart
    sub = S[np.ix_(rows, cols)]
    norms = np.linalg.norm(sub, axis=0)
    order = [int(k) for k in np.argsort(-norms, kind="stable")]
    drop: set[int] = set()
    for pos, a in enumerate(order if len(rows) > 1 else []):
        if a in drop:
            continue
        for b in order[pos + 1:]:
            if b in drop:
                continue
            cos = min(1.0, abs(float(sub[:, a] @ sub[:, b])) / (norms[a] * norms[b]))
            if math.sqrt(1.0 - cos * cos) < rtol:  # angle between the columns below ~rtol rad
                drop.add(b)
                left_out.append((parameters[cols[b]], "its gain column is parallel to that of "
                                 f"{parameters[cols[a]]} (a linear combination of it): it cannot be "
                                 "told apart from it"))
    cols = [j for k, j in enumerate(cols) if k not in drop]
    sub = S[np.ix_(rows, cols)]
    sv = np.linalg.svd(sub, compute_uv=False)
    rank = int(np.sum(sv > rtol * sv[0]))
    if rank < min(sub.shape):
        kept, dependent = _greedy_independent(sub, rtol, float(sv[0]))
    else:
        kept, dependent = list(range(sub.shape[1])), []
    for k in dependent:
        j = cols[k]
        coef = np.linalg.lstsq(sub[:, kept], sub[:, k], rcond=None)[0]
        weight = np.abs(coef) * np.linalg.norm(sub[:, kept], axis=0)
        top = [kept[q] for q in np.argsort(-weight)[:3] if weight[q] > 1e-3 * weight.max()]
        others = ", ".join(parameters[cols[q]] for q in top)
        left_out.append((parameters[j], "its gain column is (nearly) a linear combination of those of "
                                        f"{others}{' and others' if len(kept) > len(top) else ''}: "
                                        "it cannot be told apart from them"))
    cols = [cols[k] for k in kept]

    # data checks: which variables are worth tracking. The RGA stays that of all the variables
    # the parameters move (the interactions are a property of the model); the checks only
    # restrict which pairs the assignment may choose.
    Gc = tauc = None
    if check_gains is not None:
        Gc = np.asarray(check_gains, dtype=float)
        tauc = (np.full(G.shape, math.nan) if check_time_constants is None
                else np.asarray(check_time_constants, dtype=float))
        if Gc.shape != G.shape or tauc.shape != G.shape:
            raise AnalysisError(f"the gains for the data checks have shape {Gc.shape}, expected {G.shape}")
        if not np.isfinite(Gc).all():
            i, j = np.argwhere(~np.isfinite(Gc))[0]
            raise AnalysisError(f"data-check gain of {variables[i]!r} to {parameters[j]!r} is not finite")
    data = (_DataView(G if Gc is None else Gc, variables, parameters, residuals, bounds, checks,
                      structure=None if Gc is None else G)
            if residuals is not None else None)
    excluded: set[int] = set()
    var_unit, par_unit = _unit_lists(units, m, n)
    #: unit tags at their noise floor kept for their own unit's parameters (:meth:`_DataView.identifies`)
    identifying: dict[int, list[int]] = {}
    if data is not None:
        usable = np.zeros(n, dtype=bool)
        usable[cols] = True
        for i in rows:
            reason = data.row_reason(i, usable & (absS[i] >= floor))
            if reason is not None:
                own = [j for j in cols if par_unit[j] is not None and par_unit[j] == var_unit[i]]
                named = data.identifies(i, own) if data.at_floor(i) else []
                if named:
                    identifying[i] = named
                    logger.info("%s kept for %s: %s", variables[i], ", ".join(parameters[j] for j in named),
                                data.identify_reason(i, named))
                    continue
                excluded.add(i)
                left_out.append((variables[i], reason))
    floor_aware = data is not None and data.checks.closed_loop > 0 and excluded and len(excluded) < len(rows)
    if floor_aware:
        # the tags that can be tracked may not tell apart every parameter the whole matrix does
        # (the evaporator train: 8 trackable tags, 6 candidates, rank 3): keep the parameters
        # whose columns are independent there, strongest first, and say why the others go
        # Only where the trackable tags' relative gain array would not exist (rank deficient at
        # its own tolerance, rtol x 1e-3, where it used to stop `pair`): at the full matrix's rtol it
        # also dropped the single effect's inlet valve, whose trackable columns are merely close
        # to dependent, and that moved the fouling from TI-6111 to QI-6150 (3-day case, seed 0:
        # the fouling's largest error after 12 h 6.2 -> 18.7 % of its range).
        usable_rows = [i for i in rows if i not in excluded]
        sub_keep = S[np.ix_(usable_rows, cols)]
        sv = np.linalg.svd(sub_keep, compute_uv=False)
        if sv.size and int(np.sum(sv > rtol * 1e-3 * sv[0])) < min(sub_keep.shape):
            kept, dependent = _greedy_independent(sub_keep, rtol * 1e-3, float(sv[0]))
            logger.info("floor-aware pairing: the %d trackable tags tell apart %d of %d parameters",
                     len(usable_rows), len(kept), len(cols))
            for k in dependent:
                coef = np.linalg.lstsq(sub_keep[:, kept], sub_keep[:, k], rcond=None)[0]
                weight = np.abs(coef) * np.linalg.norm(sub_keep[:, kept], axis=0)
                top = [kept[q] for q in np.argsort(-weight)[:3] if weight[q] > 1e-3 * weight.max()]
                others = ", ".join(parameters[cols[q]] for q in top) or "the others"
                left_out.append((parameters[cols[k]], "on the tags worth tracking (the others are at their noise "
                                 f"floor) its gain column is (nearly) a linear combination of those of {others}: "
                                 "it cannot be told apart from them"))
            cols = [cols[k] for k in kept]
    sub = S[np.ix_(rows, cols)]

    lam_sub = relative_gain_array(sub, rtol=rtol * 1e-3,
                                  variables=[variables[i] for i in rows],
                                  parameters=[parameters[j] for j in cols])
    if floor_aware:
        # floor-aware mode: a tag left out at its noise floor cannot carry a loop, yet in a tall
        # relative gain array it takes part of a parameter's column (the evaporator's steam-chest
        # pressure took 0.78 of the fouling's, leaving its usable tags below MIN_LAMBDA): the
        # relative gains are those of the tags that can be tracked
        keep = [a for a, i in enumerate(rows) if i not in excluded]
        lam_sub = np.full(sub.shape, math.nan)
        lam_sub[keep] = relative_gain_array(sub[keep], rtol=rtol * 1e-3,
                                            variables=[variables[rows[a]] for a in keep],
                                            parameters=[parameters[j] for j in cols])
    lam = np.full((m, n), math.nan)
    lam[np.ix_(rows, cols)] = lam_sub
    cond = condition_number(sub)

    neg = [(variables[rows[a]], parameters[cols[b]], lam_sub[a, b])
           for a, b in np.argwhere(lam_sub < -1e-9)]
    big = [(variables[rows[a]], parameters[cols[b]], lam_sub[a, b])
           for a, b in np.argwhere(lam_sub > large)]
    if neg:
        warnings.append("negative relative gains (pairing there would act against the other loops): "
                        + ", ".join(f"{v}/{p} {_fmt(x)}" for v, p, x in neg[:8])
                        + (" ..." if len(neg) > 8 else ""))
    if big:
        warnings.append(f"large relative gains (> {large:g}; strong interaction, sensitive to model error): "
                        + ", ".join(f"{v}/{p} {_fmt(x)}" for v, p, x in big[:8])
                        + (" ..." if len(big) > 8 else ""))
    if cond > 1e3:
        warnings.append(f"scaled gain matrix is ill-conditioned (condition number {_fmt(cond)}): "
                        "parameter moves will be large for small errors")

    allowed = np.ones((len(rows), len(cols)), dtype=bool)
    if data is not None:
        allowed = data.allowed[np.ix_(rows, cols)].copy()
        allowed[[a for a, i in enumerate(rows) if i in excluded], :] = False
        for i, named in identifying.items():  # only for the parameters it identifies
            allowed[rows.index(i), [b for b, j in enumerate(cols) if j not in named]] = False
    G2 = tau2 = None
    flipped: dict[int, str] = {}
    if other_gains is not None:
        G2 = np.asarray(other_gains, dtype=float)
        tau2 = (np.full(G.shape, math.nan) if other_time_constants is None
                else np.asarray(other_time_constants, dtype=float))
        if G2.shape != G.shape or tau2.shape != G.shape:
            raise AnalysisError(f"gains at the second operating point have shape {G2.shape}, expected {G.shape}")
        for a, i in enumerate(rows):
            for b, j in enumerate(cols):
                own = par_unit[j] is not None and var_unit[i] == par_unit[j]  # a candidate of the block
                if G[i, j] * G2[i, j] < 0 and (lam_sub[a, b] >= min_lambda or own):
                    allowed[a, b] = False
                    flipped[i] = (f"its gain to {parameters[j]} changes sign between the operating points "
                                  f"({_fmt(G[i, j])} and {_fmt(G2[i, j])}): a loop on it would turn unstable")
    predicted: dict[int, tuple[float, float]] = {}
    # loop speed per pair (DataChecks.closed_loop_min): (variable, parameter) -> its rung of the ladder
    ladder = data.checks.ladder() if data is not None else ()
    rung: dict[tuple[int, int], int] = {}
    speeds: dict[int, float] = {}
    # pairing per unit (units): the unit parameters on their own tags, as a square block
    block_cols = [b for b, j in enumerate(cols) if par_unit[j] is not None]
    if data is not None and block_cols:
        data.bounded = True
    block: Block | None = None
    while True:
        cost = np.where((lam_sub >= min_lambda) & allowed, np.abs(lam_sub - 1.0), _FORBIDDEN)
        chosen: dict[int, int] = {}
        if block_cols:
            cost[:, block_cols] = _FORBIDDEN
            candidates = {cols[b]: [rows[a] for a in range(len(rows))
                                    if var_unit[rows[a]] == par_unit[cols[b]] and allowed[a, b]]
                          for b in block_cols}
            block = choose_block(S, candidates, min_lambda=min_lambda,
                                 rest=_rest_of(cost, rows, cols, S, data.checks.max_leak if data else math.inf,
                                               data.leak_weights if data else None))
            chosen.update(zip(block.tags, block.parameters))
            cost[[rows.index(i) for i in block.tags], :] = _FORBIDDEN
        r_idx, c_idx = linear_sum_assignment(cost)
        for a, b in zip(r_idx, c_idx):
            if cost[a, b] < _FORBIDDEN:
                chosen[rows[int(a)]] = cols[int(b)]
        if data is None or not chosen:
            break
        speeds = {i: ladder[rung.get((i, j), 0)] for i, j in chosen.items()} if ladder else {}
        if block_cols:
            # per unit, the structural check first: a unit parameter on another candidate's indicator
            # (an effect's fouling on the level controller's output, which its valve's capacity moves
            # as much) gets a loop that follows that candidate, and in a chain that loop distorts the
            # predicted tracking of every loop upstream, which would then be refused for it
            worst = data.separate(chosen, [j for j in cols if j not in chosen.values()], S)
            if worst is not None:
                allowed[rows.index(worst[0]), cols.index(worst[1])] = False
                continue
        predicted, failure = data.predict(chosen, tau if tauc is None else recording_time_constants(tau, tauc),
                                          speeds)
        worst: tuple[int, int] | None = None
        if failure is not None:
            i, j, why = failure
            if rung.get((i, j), 0) + 1 < len(ladder):   # its own loop faster before refusing the pair
                rung[(i, j)] = rung.get((i, j), 0) + 1
                logger.info("pair %s/%s: %s; predicted again with its own loop of %.0f s", variables[i],
                            parameters[j], why, ladder[rung[(i, j)]])
                continue
            data.refuse(i, j, why)
            worst = (i, j)
        else:
            worst = data.separate(chosen, [j for j in cols if j not in chosen.values()], S)
        if worst is None:
            break
        allowed[rows.index(worst[0]), cols.index(worst[1])] = False

    if data is not None and chosen and ladder and math.isfinite(data.checks.max_jitter):
        # loop noise (DataChecks.max_jitter): no loop faster than its tag's noise allows its parameter
        slowed = {}
        for i, j in chosen.items():
            quiet = data.quiet_loop(i, j, ladder)
            if quiet > speeds.get(i, ladder[0]) * (1.0 + 1e-9):
                slowed[i] = (speeds.get(i, ladder[0]), quiet)
                speeds[i] = quiet
            elif quiet == ladder[0] and data.jitter(i, j, quiet) > data.checks.max_jitter:
                warnings.append(f"pair {variables[i]}/{parameters[j]}: even with a loop of {quiet:g} s its tag's "
                                f"noise moves {parameters[j]} by {_fmt(data.jitter(i, j, quiet))} of its range "
                                f"(standard deviation; limit {data.checks.max_jitter:g})")
        if slowed:
            predicted, _ = data.predict(chosen, tau if tauc is None else recording_time_constants(tau, tauc), speeds)
            for i, (fast, slow) in slowed.items():
                j = chosen[i]
                ratio = predicted.get(i, (math.nan, math.nan))[0]
                warnings.append(f"pair {variables[i]}/{parameters[j]}: loop slowed from {fast:.0f} s to {slow:.0f} s "
                                f"(its tag's noise would move {parameters[j]} by {_fmt(data.jitter(i, j, fast))} of its "
                                f"range, {_fmt(data.jitter(i, j, slow))} with the slower loop; limit "
                                f"{data.checks.max_jitter:g}); predicted ratio {_fmt(ratio)}")
                logger.info(warnings[-1])

    pairs = []
    for i in range(m):
        if i in chosen:
            j = chosen[i]
            ratio, at_bound = predicted.get(i, (math.nan, math.nan))
            gain, t63 = float(G[i, j]), float(tau[i, j])
            if G2 is not None and tau2 is not None and abs(G2[i, j]) > abs(gain):
                gain = float(G2[i, j])
                t63 = float(tau2[i, j]) if math.isfinite(tau2[i, j]) else t63
            if Gc is not None and tauc is not None and abs(Gc[i, j]) > abs(gain):
                gain = float(Gc[i, j])
                t63 = float(tauc[i, j]) if math.isfinite(tauc[i, j]) else t63
            lam_ij = (block.lambda_of(j) if block is not None and j in block.parameters else float(lam[i, j]))
            pairs.append(Pair(variables[i], parameters[j], lam_ij, gain, t63, ratio, at_bound,
                              closed_loop=speeds.get(i, math.nan)))
            if lam_ij > large:
                warnings.append(f"pair {variables[i]}/{parameters[j]} has a large relative gain "
                                f"{_fmt(lam_ij)}")
    pairs_cond = math.nan
    if chosen:
        order_i = sorted(chosen)
        pairs_cond = condition_number(S[np.ix_(order_i, [chosen[i] for i in order_i])])
        limit = (checks or DataChecks()).max_condition if data is not None else None
        if limit is not None and pairs_cond > limit:
            warnings.append(f"the scaled gains of the chosen pairs are ill-conditioned (condition number "
                            f"{_fmt(pairs_cond)} > {limit:g}): the loops will fight each other")
    used = set(chosen.values())
    for a, i in enumerate(rows):
        if i in chosen or i in excluded:
            continue
        positive = [(lam_sub[a, b], cols[b]) for b in range(len(cols))
                    if lam_sub[a, b] >= min_lambda and allowed[a, b]]
        rejected = data.rejection(i) if data is not None else None
        if i in flipped:
            rejected = flipped[i] if rejected is None else f"{flipped[i]}; {rejected}"
        if not positive and rejected is not None and 1e-9 < lam_sub[a].max() < min_lambda:
            best = int(np.argmax(lam_sub[a]))
            reason = (f"no parameter has a relative gain of at least {min_lambda:g} with it (largest: "
                      f"{parameters[cols[best]]}, {_fmt(lam_sub[a, best])}); {rejected}")
        elif not positive and rejected is not None:
            reason = rejected
        elif not positive and (lam_sub[a] > 1e-9).any():
            best = int(np.argmax(lam_sub[a]))
            reason = (f"no parameter has a relative gain of at least {min_lambda:g} with it (largest: "
                      f"{parameters[cols[best]]}, {_fmt(lam_sub[a, best])})")
        elif not positive:
            reason = "no parameter has a positive relative gain with it"
        else:
            best_lam, j = min(positive, key=lambda t: abs(t[0] - 1.0))
            taker = next((variables[v] for v, q in chosen.items() if q == j), None)
            reason = (f"no unused parameter with a positive relative gain is left (best was {parameters[j]}, "
                      f"lambda {_fmt(best_lam)}, taken by {taker})" if taker else
                      "fewer usable parameters than variables")
            if rejected is not None:
                reason = f"{rejected}; {reason}"
        if var_unit[i] is not None and block_cols:
            reason = _unit_tag_reason(i, block, S, variables, parameters, var_unit, par_unit,
                                      [cols[b] for b in block_cols], allowed[a, block_cols],
                                      data.pair_reason if data is not None else None) + (
                "" if reason == rejected else f"; among the other parameters: {reason}")
        left_out.append((variables[i], reason))
    for b, j in enumerate(cols):
        if j in used:
            continue
        col = lam_sub[:, b]
        if par_unit[j] is not None:
            own = [rows[a] for a in range(len(rows)) if var_unit[rows[a]] == par_unit[j]]
            why = _unit_parameter_reason(j, own, block, variables, parameters, par_unit, allowed[:, b], rows,
                                         excluded, min_lambda)
            if data is not None and block is not None and any(c == j for c, _ in block.dropped):
                # what the separation check would say with it on its strongest usable tag
                free = [i for i in own if i not in chosen and i not in excluded and allowed[rows.index(i), b]]
                if free:
                    i = max(free, key=lambda r: abs(S[r, j]))
                    trial = {**chosen, i: j}
                    found = data.entangled(trial, [q for q in cols if q not in trial.values()], S)
                    if found is not None:
                        why += f"; with it on {variables[i]}, {variables[found[0]]}: {found[2]}"
            left_out.append((parameters[j], why))
            continue
        if excluded and len(excluded) == len(rows):
            reason = "no tracking variable is worth tracking (see the variables' reasons)"
        elif np.all(col <= 1e-9):
            reason = "no variable has a positive relative gain with it"
        elif data is not None and not (allowed[:, b] & (col > 1e-9)).any():
            dropped = [v for v, q, _ in data.rejected if q == parameters[j] and (v, q) not in data.apart]
            apart = [v for v, q, _ in data.rejected if q == parameters[j] and (v, q) in data.apart]
            served = ", ".join(f"{variables[rows[a]]} (lambda {_fmt(col[a])})" for a in np.argsort(-col)
                               if col[a] > 1e-9)
            reason = (f"the data checks rejected it for every variable it could serve: {served}"
                      + (f"; predicted tracking of {', '.join(dict.fromkeys(dropped))} too poor" if dropped else "")
                      + (f"; on {', '.join(dict.fromkeys(apart))} it cannot be told apart from a candidate left "
                         "unpaired (see their reasons)" if apart else "")
                      + ("" if dropped or apart else
                         "; see their reasons (it cannot close their offsets from inside its bounds, or they "
                         "are at their noise floor)"))
        elif data is not None and _best_rejected(col, allowed[:, b]) is not None:
            a_best = _best_rejected(col, allowed[:, b])
            reason = (f"the data checks rejected its best pair, with {variables[rows[a_best]]} (lambda "
                      f"{_fmt(col[a_best])}): see {variables[rows[a_best]]}")
        elif len(used) >= len(rows) - len(excluded):
            best = int(np.argmin(np.where(col > 1e-9, np.abs(col - 1.0), np.inf)))
            reason = (f"not needed: every variable is paired (closest was {variables[rows[best]]}, "
                      f"lambda {_fmt(col[best])})")
        else:
            reason = "another parameter gave relative gains closer to 1 for the variables it could serve"
        left_out.append((parameters[j], reason))

    for msg in warnings:
        logger.info(msg)
    if data is None:
        return Pairing(tuple(pairs), tuple(left_out), tuple(warnings), variables, parameters, G, S, lam, cond,
                       pairs_condition_number=pairs_cond, block=block)
    return Pairing(tuple(pairs), tuple(left_out), tuple(warnings), variables, parameters, G, S, lam, cond,
                   data.stats, data.reach, data.checks, pairs_cond, tuple(data.rejected), block=block)


def _unit_lists(units: tuple[Sequence[int | None], Sequence[int | None]] | None, m: int, n: int
                ) -> tuple[list[int | None], list[int | None]]:
    """The unit index per variable and per parameter (all None without *units*)."""
    if units is None:
        return [None] * m, [None] * n
    var_unit, par_unit = (list(units[0]), list(units[1]))
    if len(var_unit) != m or len(par_unit) != n:
        raise AnalysisError(f"units: {len(var_unit)} variable and {len(par_unit)} parameter entries for "
                            f"{m} variables and {n} parameters")
    return var_unit, par_unit


def _rest_of(cost: np.ndarray, rows: Sequence[int], cols: Sequence[int], S: np.ndarray, max_leak: float,
             weights: Callable[[Sequence[int]], np.ndarray] | None = None
             ) -> Callable[[frozenset[tuple[int, int]]], tuple[int, float, int]]:
    """``rest(block_pairs) -> (pairs, cost, entangled)`` of :func:`~trackingbox.analysis.blocks.choose_block`:
    the assignment of the other parameters on *cost* (rows: *rows*, columns: *cols*) without the rows
    the block takes, and how many of all the pairs a parameter left unpaired moves by more than
    *max_leak* of its range per range (:func:`leakage` on the scaled gains *S*; 0 when it is inf)."""
    where = {i: a for a, i in enumerate(rows)}

    def rest(taken: frozenset[tuple[int, int]]) -> tuple[int, float, int]:
        c = cost.copy()
        c[[where[i] for i, _ in taken], :] = _FORBIDDEN
        r, k = linear_sum_assignment(c)
        ok = c[r, k] < _FORBIDDEN
        entangled = 0
        if math.isfinite(max_leak):
            pairs = sorted(taken) + [(rows[int(a)], cols[int(b)]) for a, b in zip(r[ok], k[ok])]
            used = {j for _, j in pairs}
            unpaired = [j for j in cols if j not in used]
            try:
                L = np.abs(leakage(S, [i for i, _ in pairs], [j for _, j in pairs], unpaired))
                if weights is not None and L.size:
                    L = L * weights(unpaired)[None, :]
                entangled = int((L.max(axis=1) > max_leak).sum()) if L.size else 0
            except AnalysisError:   # singular pairs: as bad as every pair entangled
                entangled = len(pairs)
        return int(ok.sum()), float(c[r, k][ok].sum()), entangled

    return rest


def _unit_tag_reason(i: int, block: Block | None, S: np.ndarray, variables: Sequence[str],
                     parameters: Sequence[str], var_unit: Sequence[int | None], par_unit: Sequence[int | None],
                     block_cols: Sequence[int], allowed: np.ndarray,
                     why_not: Callable[[int, int], str | None] | None) -> str:
    """Why variable *i*, a tag of a unit, carries none of its unit's parameters (*why_not(i, j)*: the
    data checks' reason against the pair of variable *i* and parameter *j*)."""
    mine = [j for j in block_cols if par_unit[j] == var_unit[i]]
    if not mine:
        return f"a tag of unit [{var_unit[i]}], which has no candidate parameter paired per unit"
    parts = []
    for j in mine:
        k = list(block_cols).index(j)
        if not allowed[k]:
            why = why_not(i, j) if why_not is not None else None
            parts.append(f"the data checks do not allow it for {parameters[j]}" + (f" ({why})" if why else ""))
            continue
        if block is None or j not in block.parameters:
            parts.append(f"{parameters[j]} stays unpaired (see its reason)")
            continue
        a = block.parameters.index(j)
        taker = block.tags[a]
        trial = list(block.tags)
        trial[a] = i
        L = square_rga(S[np.ix_(trial, list(block.parameters))]) if i not in block.tags else None
        if L is None:
            alt = "the block would be singular" if i not in block.tags else "it is taken in the block"
        else:
            alt = (f"with it {parameters[j]}'s relative gain in the block would be {_fmt(L[a, a])} "
                   f"and the block's RGA number {_fmt(float(np.abs(L - np.eye(len(trial))).sum()))}")
        parts.append(f"{parameters[j]} pairs with {variables[taker]} (relative gain {_fmt(block.rga[a, a])} in "
                     f"the block of unit parameters, RGA number {_fmt(block.number)}); {alt}")
    return f"a tag of unit [{var_unit[i]}]: " + "; ".join(parts)


def _unit_parameter_reason(j: int, own: Sequence[int], block: Block | None, variables: Sequence[str],
                           parameters: Sequence[str], par_unit: Sequence[int | None], allowed: np.ndarray,
                           rows: Sequence[int], excluded: set[int], min_lambda: float) -> str:
    """Why parameter *j* of a unit is left unpaired."""
    unit = par_unit[j]
    if not own:
        return f"paired per unit, and no tracking variable belongs to its unit [{unit}] (twin outputs ending in [{unit}])"
    names = ", ".join(variables[i] for i in own)
    usable = [i for i in own if i not in excluded and allowed[list(rows).index(i)]]
    if not usable:
        return (f"paired per unit, and none of its unit's tags ({names}) is usable: they are at their noise "
                "floor, out of its reach or refused by the predicted tracking (see their reasons)")
    if block is not None:
        for col, best in block.dropped:
            if col != j:
                continue
            tags = ", ".join(variables[i] for i in usable)
            if not best >= min_lambda:
                return (f"paired per unit: on its unit's usable tags ({tags}) its relative gain in the block of "
                        f"unit parameters stays below the {min_lambda:g} a pair needs (at best {_fmt(best)}, the "
                        "block singular if nan): its loop would depend on the others'")
            return (f"paired per unit: on its unit's usable tags ({tags}) a pair (its own or one it displaces) could "
                    "not be told apart from a candidate left unpaired (the separation check), or it would take "
                    f"the only tag of another candidate (relative gain in the block at best {_fmt(best)})")
    return f"paired per unit; its unit's usable tags ({', '.join(variables[i] for i in usable)}) are taken"


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


def _best_rejected(col: np.ndarray, allowed: np.ndarray) -> int | None:
    """Row of the positive relative gain closest to 1 in *col* if the data checks forbade it, else None."""
    score = np.where(col > 1e-9, np.abs(col - 1.0), np.inf)
    if not np.isfinite(score).any():
        return None
    a = int(np.argmin(score))
    return None if allowed[a] else a


class _DataView:
    """The data-aware checks of :func:`choose_pairs` (see the module notes)."""

    def __init__(self, G: np.ndarray, variables: tuple[str, ...], parameters: tuple[str, ...],
                 residuals: Residuals, bounds: npt.ArrayLike | None, checks: DataChecks | None,
                 structure: np.ndarray | None = None) -> None:
        m, n = G.shape
        if bounds is None:
            raise AnalysisError("the data checks need the parameter bounds (start, min, max)")
        B = np.asarray(bounds, dtype=float)
        if B.shape != (n, 3):
            raise AnalysisError(f"bounds have shape {B.shape}, expected ({n}, 3): (start, min, max) per parameter")
        self.G, self.B = G, B
        self.variables, self.parameters = variables, parameters
        self.checks = checks or DataChecks()
        self.interval = float(residuals.interval)
        by_name = {s.variable: s for s in residuals.stats()}
        self.stats = tuple(by_name[v] for v in variables if v in by_name)
        self.stat = [by_name.get(v) for v in variables]
        R = np.full((m, residuals.time.size), math.nan)
        for i, v in enumerate(variables):
            if v in residuals.variables:
                R[i] = residuals.residual[residuals.variables.index(v)]
        self.R = R
        #: samples the closed-loop prediction leaves out at the start (see predict_tracking's settle)
        self.settle = min(R.shape[1] // 2, int(math.ceil(SETTLE_LOOPS * self.checks.closed_loop / self.interval
                                                          - 1e-9)))
        #: per variable: its noise floor over its untracked RMS error after that start-up
        self.floor_ratio = np.full(m, math.nan)
        for i, st in enumerate(self.stat):
            tail = R[i, self.settle:]
            tail = tail[np.isfinite(tail)]
            if st is not None and tail.size and math.isfinite(st.noise):
                rms = float(np.sqrt(np.mean(tail ** 2)))
                self.floor_ratio[i] = st.noise / rms if rms > 0 else math.inf
        self.reach = np.full((m, n), math.nan)
        self.moves = np.full((m, n), math.nan)
        self.allowed = np.ones((m, n), dtype=bool)
        for i, st in enumerate(self.stat):
            if st is None or st.samples == 0:
                continue
            for j in range(n):
                mv, frac = reach(float(G[i, j]), st.mean, *B[j])
                self.moves[i, j], self.reach[i, j] = mv, frac
                self.allowed[i, j] = frac >= self.checks.min_reach
        self.rejected: list[tuple[str, str, str]] = []
        #: (i, j) -> why a pair whose structure gain and data-check gain differ in sign is not allowed
        self.sign: dict[tuple[int, int], str] = {}
        if structure is not None:
            for i, j in np.argwhere(structure * G < 0):
                self.allowed[i, j] = False
                self.sign[(int(i), int(j))] = (
                    f"its gain to {parameters[j]} has one sign in the step tests that set the pairing structure "
                    f"({_fmt(structure[i, j])}) and the other with the twin run as the data were recorded "
                    f"({_fmt(G[i, j])}): a loop on it would act the wrong way")
        self._last: dict[int, str] = {}
        #: (variable, parameter) of the pairs :meth:`separate` forbade
        self.apart: set[tuple[str, str]] = set()
        #: separation per move the data allow (pairing per unit): see :meth:`leak_weights`
        self.bounded = False
        #: (variable, loop) -> loop_jitter of its untracked error (see :meth:`jitter`)
        self._jitter: dict[tuple[int, float], float] = {}

    def moved_at_most(self, j: int) -> float:
        """Largest move of candidate *j*, in fractions of its bound range (at most 1), that the untracked
        errors allow: moved by ``m``, it would move tag ``i`` by ``|g_ij| x m x range``, and no tag's
        untracked RMS error (noise included) is smaller than what it shows (a candidate that moved more
        would show in some tag, unless others cancelled it there)."""
        span = float(self.B[j, 2] - self.B[j, 1])
        best = math.inf
        for i, st in enumerate(self.stat):
            if st is None or st.samples == 0 or not math.isfinite(st.rms):
                continue
            moved = abs(float(self.G[i, j])) * span
            if moved > 0:
                best = min(best, st.rms / moved)
        return min(1.0, best)

    def jitter(self, i: int, j: int, loop: float) -> float:
        """Standard deviation of parameter *j*'s move, in fractions of its bound range, that a loop of
        *loop* s on variable *i* makes from the variable's fast error (:func:`~.offsets.loop_jitter` of
        the untracked error over the gain); inf without a gain, NaN without data."""
        key = (i, round(float(loop), 6))
        if key not in self._jitter:
            self._jitter[key] = loop_jitter(self.R[i], self.interval, float(loop))
        g = self.full_move(i, j)
        return self._jitter[key] / g if g > 0 else math.inf

    def full_move(self, i: int, j: int) -> float:
        """How far variable *i* moves (its units, magnitude) when candidate *j* moves by its whole bound range."""
        return abs(float(self.G[i, j])) * float(self.B[j, 2] - self.B[j, 1])

    def quiet_loop(self, i: int, j: int, ladder: Sequence[float]) -> float:
        """The fastest loop of *ladder* (slowest first) whose :meth:`jitter` is within ``max_jitter`` and no
        faster one above it; the slowest when none is (or when the data give no figure)."""
        out = float(ladder[0])
        for loop in ladder:
            x = self.jitter(i, j, loop)
            if not (math.isfinite(x) and x <= self.checks.max_jitter):
                break
            out = float(loop)
        return out

    def at_floor(self, i: int) -> bool:
        """Whether variable *i* is left out for its noise floor (``closed_loop`` set, its floor more than
        ``max_floor`` of its settled untracked RMS error)."""
        f = self.floor_ratio[i]
        return self.checks.closed_loop > 0 and math.isfinite(f) and f > self.checks.max_floor

    def identifies(self, i: int, candidates: Sequence[int]) -> list[int]:
        """Those of *candidates* (its own unit's parameters) that variable *i* identifies: a move of
        :data:`IDENTIFY_MOVE` of the parameter's bound range (the tolerance a tracked parameter is held
        to) shows on it as at least :data:`IDENTIFY_FLOOR` times its noise floor. A tag at its floor has a
        small untracked error in the data (the parameter has moved little so far, or other candidates
        cancel there); that says nothing about what the parameter will do to it. Left out, the
        parameter stays unpaired, and in a chain its changes go into its neighbours' loops (the
        evaporator train's last effect: its fouling moved the effect before it's steam chest 1.6 times
        as much as that effect's own, so that effect's tracked fouling carried the last one's)."""
        st = self.stat[i]
        if st is None or not st.samples or not (math.isfinite(st.noise) and st.noise > 0):
            return []
        return [j for j in candidates
                if self.full_move(i, j) * IDENTIFY_MOVE
                >= IDENTIFY_FLOOR * st.noise]

    def identify_reason(self, i: int, named: Sequence[int]) -> str:
        """Why the floor check does not leave variable *i* out (see :meth:`identifies`)."""
        st = self.stat[i]
        shows = ", ".join(f"{self.parameters[j]} by {IDENTIFY_MOVE:g} of its range moves it by "
                          f"{_fmt(self.full_move(i, j) * IDENTIFY_MOVE)}"
                          for j in named)
        return (f"its noise floor {_fmt(st.noise)} is {100 * self.floor_ratio[i]:.0f} % of its untracked RMS error, "
                f"but {shows} (at least {IDENTIFY_FLOOR:g} x the floor): it identifies its unit's parameter, "
                "so it stays a candidate for it alone")

    def leak_weights(self, unpaired: Sequence[int]) -> np.ndarray:
        """Per unpaired candidate, the factor on its leakage the separation check compares with
        ``max_leak``: 1, or with :attr:`bounded` (pairing per unit) ``m / SEPARATION_MOVE`` when the data
        bound its move ``m`` (:meth:`moved_at_most`) below :data:`SEPARATION_MOVE`. In a chain every
        effect's fouling moves every pressure upstream of it; an effect whose tags show its fouling under
        their noise (the feed end of a young train) cannot be paired, yet what it moved is as small as
        that: its bias on the paired effects is bounded by it."""
        if not self.bounded:
            return np.ones(len(unpaired))
        return np.array([min(1.0, self.moved_at_most(k) / SEPARATION_MOVE) for k in unpaired])

    def separate(self, chosen: dict[int, int], unpaired: Sequence[int], scaled: np.ndarray) -> tuple[int, int] | None:
        """The chosen pair whose parameter is worst told apart from a candidate left unpaired, if its
        leakage (:func:`leakage` of the *scaled* gains) exceeds ``max_leak``; else None."""
        found = self.entangled(chosen, unpaired, scaled)
        if found is None:
            return None
        i, j, reason = found
        self.rejected.append((self.variables[i], self.parameters[j], reason))
        self.apart.add((self.variables[i], self.parameters[j]))
        self._last[i] = reason
        logger.info("pair %s/%s rejected: %s", self.variables[i], self.parameters[j], reason)
        return i, j

    def entangled(self, chosen: dict[int, int], unpaired: Sequence[int], scaled: np.ndarray
                  ) -> tuple[int, int, str] | None:
        """:meth:`separate`'s finding (variable, parameter, reason), not recorded; None when every pair passes."""
        limit = self.checks.max_leak
        if not chosen or not len(unpaired) or not math.isfinite(limit):
            return None
        rows = sorted(chosen)
        cols = [chosen[i] for i in rows]
        try:
            L = np.abs(leakage(scaled, rows, cols, unpaired))
        except AnalysisError as exc:
            logger.info("separation check skipped: %s", exc)
            return None
        weight = self.leak_weights(unpaired)
        a, b = np.unravel_index(int(np.argmax(L * weight)), L.shape)
        if not L[a, b] * weight[b] > limit:
            return None
        i, j, k = rows[a], cols[a], unpaired[b]
        reason = (f"paired with {self.parameters[j]} it cannot be told apart from {self.parameters[k]}, which no "
                  f"loop tracks: at steady state a move of {self.parameters[k]} by its bound range moves "
                  f"{self.parameters[j]} by {_fmt(float(L[a, b]))} of its own (limit {limit:g}"
                  + (f"; the data allow {self.parameters[k]} a move of {_fmt(self.moved_at_most(k))} of its range, "
                     f"so the limit applies to {_fmt(float(L[a, b] * weight[b]))}" if weight[b] < 1.0 else "")
                  + f"), so {self.parameters[j]}'s trajectory would show {self.parameters[k]}'s changes")
        return i, j, reason

    def row_reason(self, i: int, usable: np.ndarray) -> str | None:
        """Why variable *i* is left out before the RGA (noise level, no reachable parameter), or None."""
        st = self.stat[i]
        if st is None or st.samples == 0:
            return None
        c = self.checks
        if c.closed_loop > 0:
            f = self.floor_ratio[i]
            if math.isfinite(f) and f > c.max_floor:
                return (f"its noise floor {_fmt(st.noise)} (estimated from the data) is {100 * f:.0f} % of its "
                        f"untracked RMS error once loops of {c.closed_loop:g} s settled: no loop brings it under "
                        f"{100 * c.max_floor:.0f} %")
        elif st.noise_ratio < c.noise_ratio:
            return (f"its untracked error is at noise level: RMS {_fmt(st.rms)} (mean {_fmt(st.mean)}) is "
                    f"below {c.noise_ratio:g} x the sensor noise {_fmt(st.noise)} estimated from the data "
                    "(nothing to track)")
        ok = usable & self.allowed[i]
        if ok.any():
            return None
        cand = np.flatnonzero(usable)
        if cand.size == 0:
            return None
        signs = [self.sign[(i, int(j))] for j in cand if (i, int(j)) in self.sign
                 and self.reach[i, j] >= self.checks.min_reach]
        if signs:
            return signs[0]
        j = int(cand[np.argmax(np.nan_to_num(self.reach[i, cand], nan=-1.0))])
        return (f"no candidate parameter can close its offset from inside its bounds: the remaining range of "
                f"{self.parameters[j]} moves {self.variables[i]} by {_fmt(self.moves[i, j])} toward the "
                f"measurement, the offset is {_fmt(st.mean)} (mean of measured - untracked; needs "
                f"{self.checks.min_reach:g} x)")

    def predict(self, chosen: dict[int, int], tau: np.ndarray, loops: dict[int, float] | None = None
                ) -> tuple[dict[int, tuple[float, float]], tuple[int, int, str] | None]:
        """Predicted ratio and time at a bound per chosen pair, and the worst pair above ``max_ratio``
        with its reason (or None; :meth:`refuse` records a refusal). *loops*: variable -> its loop's
        closed-loop time constant (s), default ``closed_loop``."""
        rows = [i for i in sorted(chosen) if self.stat[i] is not None and self.stat[i].samples > 0]
        if not rows:
            return {}, None
        cols = [chosen[i] for i in rows]
        loops = loops or {}
        speed = [float(loops.get(i, self.checks.closed_loop)) for i in rows]
        taus = np.array([max(tau[i, j] if math.isfinite(tau[i, j]) and tau[i, j] > 0 else self.interval, c)
                         for i, j, c in zip(rows, cols, speed)]) + 0.5 * self.interval
        lo = self.B[cols, 1] - self.B[cols, 0]
        hi = self.B[cols, 2] - self.B[cols, 0]
        try:
            pr = predict_tracking(self.G[np.ix_(rows, cols)], taus, self.R[rows], lo, hi, self.interval,
                                  settle=SETTLE_LOOPS * self.checks.closed_loop)
        except AnalysisError as exc:
            logger.info("tracking prediction skipped: %s", exc)
            return {}, None
        out = {i: (float(pr.ratio[a]), float(pr.at_bound[a])) for a, i in enumerate(rows)}
        ratio = np.nan_to_num(pr.ratio, nan=-1.0)
        floor = self.checks.closed_loop > 0
        if floor:  # judged on the error above the noise floor
            f = np.clip(np.nan_to_num(self.floor_ratio[rows], nan=0.0), 0.0, 0.999)
            ratio = np.where(ratio >= 0, np.sqrt(np.clip(ratio ** 2 - f ** 2, 0.0, None) / (1.0 - f ** 2)), ratio)
        a = int(np.argmax(ratio))
        if ratio[a] <= self.checks.max_ratio:
            return out, None
        i, j = rows[a], cols[a]
        if floor:
            own = speed[a] != self.checks.closed_loop
            loop = (f"its own loop of {speed[a]:.0f} s, the fastest allowed (the others' up to "
                    f"{self.checks.closed_loop:g} s)" if own else f"loops of {self.checks.closed_loop:g} s")
            reason = (f"paired with {self.parameters[j]} (together with the other pairs) tracking would leave "
                      f"{100 * ratio[a]:.0f} % of its untracked RMS error above its noise floor (limit "
                      f"{100 * self.checks.max_ratio:.0f} %; {100 * pr.ratio[a]:.0f} % of the whole error; {loop}: "
                      "what changes faster stays)")
        else:
            reason = (f"paired with {self.parameters[j]} (together with the other pairs) tracking would leave "
                      f"{100 * ratio[a]:.0f} % of its untracked RMS error (limit {100 * self.checks.max_ratio:.0f} %)")
        if pr.at_bound[a] > 0.05:
            reason += f"; {self.parameters[j]} would sit at a bound {100 * pr.at_bound[a]:.0f} % of the time"
        if math.isfinite(pr.need[a]) and pr.need[a] > 1.0:
            reason += (f" (closing the mean offsets needs {pr.need[a]:.2g} x its remaining range)")
        return out, (i, j, reason)

    def refuse(self, i: int, j: int, reason: str) -> None:
        """Record that the prediction refused the pair of variable *i* with parameter *j*."""
        self.rejected.append((self.variables[i], self.parameters[j], reason))
        self._last[i] = reason
        logger.info("pair %s/%s rejected: %s", self.variables[i], self.parameters[j], reason)

    def pair_reason(self, i: int, j: int) -> str | None:
        """Why the data checks do not allow the pair of variable *i* and parameter *j*: the last refusal of
        that pair, a sign change, or the parameter's reach; None when none applies."""
        for v, q, why in reversed(self.rejected):
            if (v, q) == (self.variables[i], self.parameters[j]):
                return why
        if (i, j) in self.sign:
            return self.sign[(i, j)]
        st = self.stat[i]
        if st is not None and st.samples and self.reach[i, j] < self.checks.min_reach:
            return (f"the remaining range of {self.parameters[j]} moves it by only {_fmt(self.moves[i, j])} toward "
                    f"the measurement, the offset is {_fmt(st.mean)}")
        return None

    def rejection(self, i: int) -> str | None:
        """The last prediction-based rejection of a pair of variable *i*, or a reach reason, or None."""
        if i in self._last:
            return self._last[i]
        st = self.stat[i]
        if st is None or st.samples == 0 or self.allowed[i].all():
            return None
        signs = [why for (a, _), why in self.sign.items() if a == i]
        if signs and not (self.reach[i] >= self.checks.min_reach).any():
            return signs[0]
        j = int(np.argmax(np.nan_to_num(np.where(self.allowed[i], -1.0, self.reach[i]), nan=-1.0)))
        return (f"the remaining range of {self.parameters[j]} moves it by only {_fmt(self.moves[i, j])} "
                f"toward the measurement, the offset is {_fmt(st.mean)}")


def leakage(scaled: npt.ArrayLike, rows: Sequence[int], cols: Sequence[int], unpaired: Sequence[int]) -> np.ndarray:
    """How far the paired parameters move per move of the candidates left unpaired (steady state).

    With one integrating loop per pair (variable ``rows[a]`` driven by parameter ``cols[a]``)
    every paired variable returns to its measurement, so the loops' parameter moves ``dp``
    answer the unpaired candidates' moves ``du`` by ``S_pp dp + S_pu du = 0``:
    ``dp = -L du`` with ``L = S_pp^-1 S_pu``. In scaled gains (variables by their ranges,
    parameters by their bound ranges) ``L[a, b]`` is the fraction of its bound range that
    parameter ``cols[a]`` moves when candidate ``unpaired[b]`` moves by its bound range: the
    part of the tracked trajectory that is the other candidate's change, not its own.

    Parameters
    ----------
    scaled : array_like, shape (m, n)
        Scaled gain matrix.
    rows, cols : sequence of int, same length k
        The pairs: row ``rows[a]`` paired with column ``cols[a]``.
    unpaired : sequence of int
        Columns of the candidates left unpaired.

    Returns
    -------
    ndarray, shape (k, len(unpaired))

    Raises
    ------
    AnalysisError
        If the pairs' gains are singular or the indices do not match.

    Examples
    --------
    Tag y1 paired with a, y2 with b, c unpaired (hand-solved: ``b = 0.5``, ``2a + b = 1``):

    >>> leakage([[2.0, 1.0, 1.0], [0.0, 1.0, 0.5]], [0, 1], [0, 1], [2]).round(6).tolist()
    [[0.25], [0.5]]
    """
    S = np.asarray(scaled, dtype=float)
    rows, cols, unpaired = list(rows), list(cols), list(unpaired)
    if len(rows) != len(cols) or len(set(rows)) != len(rows) or len(set(cols)) != len(cols):
        raise AnalysisError(f"leakage: {len(rows)} paired rows and {len(cols)} paired columns must match one to one")
    if set(cols) & set(unpaired):
        raise AnalysisError("leakage: a column is both paired and unpaired")
    Spp = S[np.ix_(rows, cols)]
    Spu = S[np.ix_(rows, unpaired)]
    if not rows or not unpaired:
        return np.zeros((len(rows), len(unpaired)))
    sv = np.linalg.svd(Spp, compute_uv=False)
    if not (sv[-1] > 1e-12 * sv[0]):
        raise AnalysisError("leakage: the scaled gains of the pairs are singular")
    return np.linalg.solve(Spp, Spu)


def complete_with_recording(first: Pairing, gains: npt.ArrayLike, *, time_constants: npt.ArrayLike,
                            variable_ranges: npt.ArrayLike, parameter_ranges: npt.ArrayLike,
                            residuals: Residuals, bounds: npt.ArrayLike, checks: DataChecks | None = None,
                            rtol: float = RANK_RTOL, min_lambda: float = MIN_LAMBDA) -> Pairing:
    """Pair the tags a freeze hides, with the gains of the twin as the data were recorded.

    With the controllers frozen a controller's output (a pump speed, a heating
    medium's temperature) moves with no parameter, yet with the controllers active,
    as the data were recorded, that output is where a parameter error shows: the
    loop holds its measurement at the setpoint and moves its output instead. Those
    tags (no parameter moves them by more than :data:`NEGLIGIBLE` x the largest
    scaled gain in *first*) are paired here from the RGA of *gains* (step tests
    with nothing frozen) over them and the tags *first* paired, with the same data
    checks; the pairs of *first* are kept, and a hidden tag gets the parameter
    this RGA gives it unless *first* already uses that parameter. All pairs are
    then predicted together with *gains*; while a pair added here would leave
    more than ``max_ratio`` of its error, the worst is dropped.

    Parameters
    ----------
    first : Pairing
        :func:`choose_pairs` on the frozen gains (with ``check_gains``).
    gains, time_constants : array_like, shape (m, n)
        Step tests with nothing frozen, same rows and columns as *first*.
    variable_ranges, parameter_ranges, residuals, bounds, checks, rtol, min_lambda
        As for :func:`choose_pairs`.

    Returns
    -------
    Pairing
        *first* with the added pairs (``rga_from = "recording"``), the reasons of
        the hidden tags left out replaced by this pass's, and its rejections added.
    """
    G = np.asarray(gains, dtype=float)
    tau = np.asarray(time_constants, dtype=float)
    V, P = first.variables, first.parameters
    if G.shape != (len(V), len(P)) or tau.shape != G.shape:
        raise AnalysisError(f"recorded gains have shape {G.shape}, expected {(len(V), len(P))}")
    absS = np.abs(first.scaled_gains)
    top = float(absS.max()) if absS.size else 0.0
    hidden = [i for i in range(len(V)) if top > 0 and absS[i].max() < NEGLIGIBLE * top]
    if not hidden:
        return first
    index = {v: i for i, v in enumerate(V)}
    kept = {index[p.variable]: p for p in first.pairs}
    rows = sorted(set(kept) | set(hidden))
    names = [V[i] for i in rows]
    have = [v for v in names if v in residuals.variables]
    second = choose_pairs(G[rows], names, P, time_constants=tau[rows],
                          variable_ranges=np.asarray(variable_ranges, dtype=float)[rows],
                          parameter_ranges=parameter_ranges, residuals=residuals.subset(have), bounds=bounds,
                          checks=checks, rtol=rtol, min_lambda=min_lambda)
    used = {p.parameter for p in first.pairs}
    added: list[Pair] = []
    reasons = dict(second.left_out)
    for p in second.pairs:
        if index[p.variable] not in hidden:
            continue
        if p.parameter in used:
            taker = next(q.variable for q in first.pairs if q.parameter == p.parameter)
            reasons[p.variable] = (f"with the controllers active its relative gain points to {p.parameter} "
                                   f"(lambda {_fmt(p.lambda_)}), which the frozen structure pairs with {taker}")
            continue
        added.append(Pair(p.variable, p.parameter, p.lambda_, p.gain, p.time_constant, p.predicted_ratio,
                          p.at_bound, rga_from="recording", closed_loop=p.closed_loop))
    # every pair together, with the recorded gains: drop the worst added pair while it would fail
    data = _DataView(G, V, P, residuals, bounds, checks)
    dropped: list[tuple[str, str, str]] = []
    warnings = list(first.warnings) + [f"(controllers active) {w}" for w in second.warnings]
    predicted: dict[int, tuple[float, float]] = {}
    while True:
        chosen = {index[p.variable]: P.index(p.parameter) for p in (*first.pairs, *added)}
        # each pass's own loops where it chose them (closed_loop_min), else the spec's closed_loop
        loops = {index[p.variable]: p.closed_loop for p in (*first.pairs, *added) if math.isfinite(p.closed_loop)}
        predicted, failure = data.predict(chosen, tau, loops)
        if failure is None:
            break
        data.refuse(*failure)
        worst, why = failure[:2], failure[2]
        if not any(index[p.variable] == worst[0] for p in added):
            warnings.append(f"with the pairs added for the tags the freeze hides, {V[worst[0]]}/{P[worst[1]]}: "
                            f"{why}")
            break
        dropped.append((V[worst[0]], P[worst[1]], why))
        reasons[V[worst[0]]] = why
        added = [p for p in added if index[p.variable] != worst[0]]
    hidden_names = {V[i] for i in hidden}
    paired = {p.variable for p in added} | {p.parameter for p in added}
    left: list[tuple[str, str]] = []
    for name, why in first.left_out:
        if name in paired:
            continue
        if name in hidden_names and name in reasons:
            why = (f"no parameter moves it with the controllers frozen; with them active (as the data were "
                   f"recorded): {reasons[name]}")
        left.append((name, why))
    pairs = tuple(replace_ratio(p, predicted.get(index[p.variable]))
                  for p in sorted([*first.pairs, *added], key=lambda p: index[p.variable]))
    return replace(first, pairs=pairs, left_out=tuple(left), warnings=tuple(warnings),
                   rejected=first.rejected + tuple(second.rejected) + tuple(dropped))


def replace_ratio(p: Pair, figures: tuple[float, float] | None) -> Pair:
    """*p* with the predicted ratio and time at a bound *figures* (unchanged when None)."""
    if figures is None:
        return p
    return replace(p, predicted_ratio=float(figures[0]), at_bound=float(figures[1]))
