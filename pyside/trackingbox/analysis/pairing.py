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
(:meth:`DataView.leak_weights`).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from ..errors import AnalysisError
from .blocks import Block, choose_block
from .data_checks import DataView, best_rejected, leakage
from .offsets import Residuals
from .pairing_model import (
    FORBIDDEN,
    IDENTIFY_FLOOR,
    IDENTIFY_MOVE,
    LADDER_STEP,
    LARGE_LAMBDA,
    MIN_LAMBDA,
    NEGLIGIBLE,
    RANK_RTOL,
    SEPARATION_MOVE,
    SETTLE_LOOPS,
    DataChecks,
    Pair,
    Pairing,
    fmt,
    loop_ladder,
    recording_time_constants,
    replace_ratio,
)
from .rga import _greedy_independent, condition_number, relative_gain_array, scale_gains
from .unit_pairing import rest_of, unit_lists, unit_parameter_reason, unit_tag_reason

logger = logging.getLogger(__name__)

#: The pairing's names: the choice here, what a pairing is (:mod:`.pairing_model`) and the data
#: checks (:mod:`.data_checks`), importable from here as before.
__all__ = [
    "choose_pairs", "complete_with_recording", "PairingSettings", "DataChecks", "Pair", "Pairing", "loop_ladder",
    "leakage", "recording_time_constants", "replace_ratio", "LARGE_LAMBDA", "NEGLIGIBLE", "RANK_RTOL",
    "MIN_LAMBDA", "SETTLE_LOOPS", "LADDER_STEP", "SEPARATION_MOVE", "IDENTIFY_MOVE", "IDENTIFY_FLOOR",
]

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
    settings = PairingSettings(negligible=negligible, large=large, rtol=rtol, min_lambda=min_lambda, checks=checks)
    w = _Work.start(gains, variables, parameters, time_constants, variable_ranges, parameter_ranges)
    if w.all_zero():
        return w.zero_pairing()
    w.leave_out_negligible(settings)
    w.leave_out_dependent(settings)
    w.data_checks(check_gains, check_time_constants, residuals, bounds, checks, units)
    w.leave_out_dependent_on_trackable(settings)
    w.relative_gains(settings)
    w.allow(other_gains, other_time_constants, settings)
    w.assign(settings)
    w.limit_loop_noise()
    pairs = w.pairs(settings)
    w.explain_unpaired_variables(settings)
    w.explain_unused_parameters(settings)
    return w.pairing(pairs, checks)


@dataclass(frozen=True)
class PairingSettings:
    """The thresholds of :func:`choose_pairs` (its keywords of the same names)."""

    negligible: float = NEGLIGIBLE
    large: float = LARGE_LAMBDA
    rtol: float = RANK_RTOL
    min_lambda: float = MIN_LAMBDA
    checks: DataChecks | None = None


@dataclass
class _Work:
    """The state :func:`choose_pairs` builds step by step (each method one named step, in order).

    ``rows``/``cols`` are the variables and parameters still in the choice, ``left_out``
    the reasons of those that left it, ``allowed`` the pairs the assignment may take.
    """

    G: np.ndarray
    tau: np.ndarray
    S: np.ndarray
    variables: tuple[str, ...]
    parameters: tuple[str, ...]
    left_out: list[tuple[str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    rows: list[int] = field(default_factory=list)
    cols: list[int] = field(default_factory=list)
    floor: float = 0.0
    Gc: np.ndarray | None = None
    tauc: np.ndarray | None = None
    data: DataView | None = None
    excluded: set[int] = field(default_factory=set)
    var_unit: list[int | None] = field(default_factory=list)
    par_unit: list[int | None] = field(default_factory=list)
    #: unit tags at their noise floor kept for their own unit's parameters (:meth:`DataView.identifies`)
    identifying: dict[int, list[int]] = field(default_factory=dict)
    floor_aware: bool = False
    sub: np.ndarray | None = None
    lam_sub: np.ndarray | None = None
    lam: np.ndarray | None = None
    cond: float = math.nan
    allowed: np.ndarray | None = None
    G2: np.ndarray | None = None
    tau2: np.ndarray | None = None
    flipped: dict[int, str] = field(default_factory=dict)
    predicted: dict[int, tuple[float, float]] = field(default_factory=dict)
    ladder: tuple[float, ...] = ()
    speeds: dict[int, float] = field(default_factory=dict)
    block_cols: list[int] = field(default_factory=list)
    block: Block | None = None
    chosen: dict[int, int] = field(default_factory=dict)
    pairs_cond: float = math.nan

    @property
    def m(self) -> int:
        return self.G.shape[0]

    @property
    def n(self) -> int:
        return self.G.shape[1]

    @classmethod
    def start(cls, gains: npt.ArrayLike, variables: Sequence[str], parameters: Sequence[str],
              time_constants: npt.ArrayLike | None, variable_ranges: npt.ArrayLike | None,
              parameter_ranges: npt.ArrayLike | None) -> _Work:
        """Check the names and shapes, and scale the gains."""
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
        return cls(G, tau, scale_gains(G, variable_ranges, parameter_ranges), variables, parameters)

    def all_zero(self) -> bool:
        absS = np.abs(self.S)
        return (float(absS.max()) if absS.size else 0.0) == 0.0

    def zero_pairing(self) -> Pairing:
        """Nothing moves anything: every name left out, with the reason."""
        for v in self.variables:
            self.left_out.append((v, "no candidate parameter changes it (all gains are zero)"))
        for p in self.parameters:
            self.left_out.append((p, "changes no tracking variable (all gains are zero)"))
        return Pairing((), tuple(self.left_out), ("gain matrix is all zeros",), self.variables, self.parameters,
                       self.G, self.S, np.full((self.m, self.n), math.nan), math.inf)

    def leave_out_negligible(self, settings: PairingSettings) -> None:
        """Parameters and variables whose largest scaled gain is below ``negligible`` x the largest."""
        absS = np.abs(self.S)
        top = float(absS.max())
        negligible = settings.negligible
        self.floor = negligible * top
        col_ok = absS.max(axis=0) >= self.floor
        row_ok = absS.max(axis=1) >= negligible * top
        for j in np.flatnonzero(~col_ok):
            self.left_out.append((self.parameters[j], f"negligible gain: its largest scaled gain "
                                  f"{fmt(absS[:, j].max())} is below {negligible:g} x the largest in the matrix "
                                  f"({fmt(top)})"))
        for i in np.flatnonzero(~row_ok):
            self.left_out.append((self.variables[i], f"no candidate parameter moves it: largest scaled gain "
                                  f"{fmt(absS[i].max())} is below {negligible:g} x {fmt(top)}"))
        self.rows = [int(i) for i in np.flatnonzero(row_ok)]
        self.cols = [int(j) for j in np.flatnonzero(col_ok)]

    def leave_out_dependent(self, settings: PairingSettings) -> None:
        """Parameters whose gain column is parallel to, or a linear combination of, stronger ones."""
        rows, cols, S, parameters, rtol = self.rows, self.cols, self.S, self.parameters, settings.rtol
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
                    self.left_out.append((parameters[cols[b]], "its gain column is parallel to that of "
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
            self.left_out.append((parameters[j], "its gain column is (nearly) a linear combination of those of "
                                  f"{others}{' and others' if len(kept) > len(top) else ''}: "
                                  "it cannot be told apart from them"))
        self.cols = [cols[k] for k in kept]

    def data_checks(self, check_gains: npt.ArrayLike | None, check_time_constants: npt.ArrayLike | None,
                    residuals: Residuals | None, bounds: npt.ArrayLike | None, checks: DataChecks | None,
                    units: tuple[Sequence[int | None], Sequence[int | None]] | None) -> None:
        """Which variables are worth tracking (with data).

        The RGA stays that of all the variables the parameters move (the interactions are a
        property of the model); the checks only restrict which pairs the assignment may choose.
        """
        G, variables, parameters = self.G, self.variables, self.parameters
        if check_gains is not None:
            self.Gc = np.asarray(check_gains, dtype=float)
            self.tauc = (np.full(G.shape, math.nan) if check_time_constants is None
                         else np.asarray(check_time_constants, dtype=float))
            if self.Gc.shape != G.shape or self.tauc.shape != G.shape:
                raise AnalysisError(f"the gains for the data checks have shape {self.Gc.shape}, expected {G.shape}")
            if not np.isfinite(self.Gc).all():
                i, j = np.argwhere(~np.isfinite(self.Gc))[0]
                raise AnalysisError(f"data-check gain of {variables[i]!r} to {parameters[j]!r} is not finite")
        self.data = (DataView(G if self.Gc is None else self.Gc, variables, parameters, residuals, bounds, checks,
                              structure=None if self.Gc is None else G)
                     if residuals is not None else None)
        self.var_unit, self.par_unit = unit_lists(units, self.m, self.n)
        data = self.data
        if data is None:
            return
        absS = np.abs(self.S)
        usable = np.zeros(self.n, dtype=bool)
        usable[self.cols] = True
        for i in self.rows:
            reason = data.row_reason(i, usable & (absS[i] >= self.floor))
            if reason is not None:
                own = [j for j in self.cols if self.par_unit[j] is not None and self.par_unit[j] == self.var_unit[i]]
                named = data.identifies(i, own) if data.at_floor(i) else []
                if named:
                    self.identifying[i] = named
                    logger.info("%s kept for %s: %s", variables[i], ", ".join(parameters[j] for j in named),
                                data.identify_reason(i, named))
                    continue
                self.excluded.add(i)
                self.left_out.append((variables[i], reason))

    def leave_out_dependent_on_trackable(self, settings: PairingSettings) -> None:
        """Floor-aware: the parameters the tags that can be tracked tell apart, strongest first.

        The tags that can be tracked may not tell apart every parameter the whole matrix does
        (the evaporator train: 8 trackable tags, 6 candidates, rank 3). Only where the trackable
        tags' relative gain array would not exist (rank deficient at its own tolerance, rtol x
        1e-3, where it used to stop `pair`): at the full matrix's rtol it also dropped the single
        effect's inlet valve, whose trackable columns are merely close to dependent, and that moved
        the fouling from TI-6111 to QI-6150 (3-day case, seed 0: the fouling's largest error after
        12 h 6.2 -> 18.7 % of its range).
        """
        data, rows, cols, excluded = self.data, self.rows, self.cols, self.excluded
        self.floor_aware = bool(data is not None and data.checks.closed_loop > 0 and excluded
                                and len(excluded) < len(rows))
        if self.floor_aware:
            rtol = settings.rtol
            usable_rows = [i for i in rows if i not in excluded]
            sub_keep = self.S[np.ix_(usable_rows, cols)]
            sv = np.linalg.svd(sub_keep, compute_uv=False)
            if sv.size and int(np.sum(sv > rtol * 1e-3 * sv[0])) < min(sub_keep.shape):
                kept, dependent = _greedy_independent(sub_keep, rtol * 1e-3, float(sv[0]))
                logger.info("floor-aware pairing: the %d trackable tags tell apart %d of %d parameters",
                            len(usable_rows), len(kept), len(cols))
                for k in dependent:
                    coef = np.linalg.lstsq(sub_keep[:, kept], sub_keep[:, k], rcond=None)[0]
                    weight = np.abs(coef) * np.linalg.norm(sub_keep[:, kept], axis=0)
                    top = [kept[q] for q in np.argsort(-weight)[:3] if weight[q] > 1e-3 * weight.max()]
                    others = ", ".join(self.parameters[cols[q]] for q in top) or "the others"
                    self.left_out.append((self.parameters[cols[k]], "on the tags worth tracking (the others are at "
                                          "their noise floor) its gain column is (nearly) a linear combination of "
                                          f"those of {others}: it cannot be told apart from them"))
                self.cols = [cols[k] for k in kept]
        self.sub = self.S[np.ix_(self.rows, self.cols)]

    def relative_gains(self, settings: PairingSettings) -> None:
        """The relative gain array of what remains, its condition number and the warnings it calls for."""
        rows, cols, sub, rtol, large = self.rows, self.cols, self.sub, settings.rtol, settings.large
        variables, parameters = self.variables, self.parameters
        assert sub is not None
        lam_sub = relative_gain_array(sub, rtol=rtol * 1e-3, variables=[variables[i] for i in rows],
                                      parameters=[parameters[j] for j in cols])
        if self.floor_aware:
            # floor-aware mode: a tag left out at its noise floor cannot carry a loop, yet in a tall
            # relative gain array it takes part of a parameter's column (the evaporator's steam-chest
            # pressure took 0.78 of the fouling's, leaving its usable tags below MIN_LAMBDA): the
            # relative gains are those of the tags that can be tracked
            keep = [a for a, i in enumerate(rows) if i not in self.excluded]
            lam_sub = np.full(sub.shape, math.nan)
            lam_sub[keep] = relative_gain_array(sub[keep], rtol=rtol * 1e-3,
                                                variables=[variables[rows[a]] for a in keep],
                                                parameters=[parameters[j] for j in cols])
        self.lam_sub = lam_sub
        self.lam = np.full((self.m, self.n), math.nan)
        self.lam[np.ix_(rows, cols)] = lam_sub
        self.cond = cond = condition_number(sub)
        neg = [(variables[rows[a]], parameters[cols[b]], lam_sub[a, b]) for a, b in np.argwhere(lam_sub < -1e-9)]
        big = [(variables[rows[a]], parameters[cols[b]], lam_sub[a, b]) for a, b in np.argwhere(lam_sub > large)]
        if neg:
            self.warnings.append("negative relative gains (pairing there would act against the other loops): "
                                 + ", ".join(f"{v}/{p} {fmt(x)}" for v, p, x in neg[:8])
                                 + (" ..." if len(neg) > 8 else ""))
        if big:
            self.warnings.append(f"large relative gains (> {large:g}; strong interaction, sensitive to model "
                                 "error): " + ", ".join(f"{v}/{p} {fmt(x)}" for v, p, x in big[:8])
                                 + (" ..." if len(big) > 8 else ""))
        if cond > 1e3:
            self.warnings.append(f"scaled gain matrix is ill-conditioned (condition number {fmt(cond)}): "
                                 "parameter moves will be large for small errors")

    def allow(self, other_gains: npt.ArrayLike | None, other_time_constants: npt.ArrayLike | None,
              settings: PairingSettings) -> None:
        """The pairs the assignment may take: the data checks' and those whose gain keeps its sign."""
        rows, cols, data, G = self.rows, self.cols, self.data, self.G
        assert self.lam_sub is not None
        allowed = np.ones((len(rows), len(cols)), dtype=bool)
        if data is not None:
            allowed = data.allowed[np.ix_(rows, cols)].copy()
            allowed[[a for a, i in enumerate(rows) if i in self.excluded], :] = False
            for i, named in self.identifying.items():  # only for the parameters it identifies
                allowed[rows.index(i), [b for b, j in enumerate(cols) if j not in named]] = False
        if other_gains is not None:
            G2 = self.G2 = np.asarray(other_gains, dtype=float)
            self.tau2 = (np.full(G.shape, math.nan) if other_time_constants is None
                         else np.asarray(other_time_constants, dtype=float))
            if G2.shape != G.shape or self.tau2.shape != G.shape:
                raise AnalysisError(f"gains at the second operating point have shape {G2.shape}, expected {G.shape}")
            for a, i in enumerate(rows):
                for b, j in enumerate(cols):
                    own = self.par_unit[j] is not None and self.var_unit[i] == self.par_unit[j]  # of the block
                    if G[i, j] * G2[i, j] < 0 and (self.lam_sub[a, b] >= settings.min_lambda or own):
                        allowed[a, b] = False
                        self.flipped[i] = (f"its gain to {self.parameters[j]} changes sign between the operating "
                                           f"points ({fmt(G[i, j])} and {fmt(G2[i, j])}): a loop on it would turn "
                                           "unstable")
        self.allowed = allowed

    def assign(self, settings: PairingSettings) -> None:
        """Assign by ``|lambda - 1|``, then judge the chosen set with the data and assign again until it holds."""
        rows, cols, S, data, allowed = self.rows, self.cols, self.S, self.data, self.allowed
        lam_sub, min_lambda, variables, parameters = self.lam_sub, settings.min_lambda, self.variables, self.parameters
        assert lam_sub is not None and allowed is not None
        # loop speed per pair (DataChecks.closed_loop_min): (variable, parameter) -> its rung of the ladder
        ladder = self.ladder = data.checks.ladder() if data is not None else ()
        rung: dict[tuple[int, int], int] = {}
        # pairing per unit (units): the unit parameters on their own tags, as a square block
        block_cols = self.block_cols = [b for b, j in enumerate(cols) if self.par_unit[j] is not None]
        if data is not None and block_cols:
            data.bounded = True
        tau = self.tau if self.tauc is None else recording_time_constants(self.tau, self.tauc)
        while True:
            cost = np.where((lam_sub >= min_lambda) & allowed, np.abs(lam_sub - 1.0), FORBIDDEN)
            chosen: dict[int, int] = {}
            if block_cols:
                cost[:, block_cols] = FORBIDDEN
                candidates = {cols[b]: [rows[a] for a in range(len(rows))
                                        if self.var_unit[rows[a]] == self.par_unit[cols[b]] and allowed[a, b]]
                              for b in block_cols}
                self.block = choose_block(S, candidates, min_lambda=min_lambda,
                                          rest=rest_of(cost, rows, cols, S,
                                                        data.checks.max_leak if data else math.inf,
                                                        data.leak_weights if data else None))
                chosen.update(zip(self.block.tags, self.block.parameters))
                cost[[rows.index(i) for i in self.block.tags], :] = FORBIDDEN
            r_idx, c_idx = linear_sum_assignment(cost)
            for a, b in zip(r_idx, c_idx):
                if cost[a, b] < FORBIDDEN:
                    chosen[rows[int(a)]] = cols[int(b)]
            self.chosen = chosen
            if data is None or not chosen:
                break
            self.speeds = {i: ladder[rung.get((i, j), 0)] for i, j in chosen.items()} if ladder else {}
            if block_cols:
                # per unit, the structural check first: a unit parameter on another candidate's indicator
                # (an effect's fouling on the level controller's output, which its valve's capacity moves
                # as much) gets a loop that follows that candidate, and in a chain that loop distorts the
                # predicted tracking of every loop upstream, which would then be refused for it
                worst = data.separate(chosen, [j for j in cols if j not in chosen.values()], S)
                if worst is not None:
                    allowed[rows.index(worst[0]), cols.index(worst[1])] = False
                    continue
            self.predicted, failure = data.predict(chosen, tau, self.speeds)
            worst = None
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

    def limit_loop_noise(self) -> None:
        """Loop noise (DataChecks.max_jitter): no loop faster than its tag's noise allows its parameter."""
        data, chosen, ladder, speeds = self.data, self.chosen, self.ladder, self.speeds
        if not (data is not None and chosen and ladder and math.isfinite(data.checks.max_jitter)):
            return
        variables, parameters = self.variables, self.parameters
        slowed = {}
        for i, j in chosen.items():
            quiet = data.quiet_loop(i, j, ladder)
            if quiet > speeds.get(i, ladder[0]) * (1.0 + 1e-9):
                slowed[i] = (speeds.get(i, ladder[0]), quiet)
                speeds[i] = quiet
            elif quiet == ladder[0] and data.jitter(i, j, quiet) > data.checks.max_jitter:
                self.warnings.append(f"pair {variables[i]}/{parameters[j]}: even with a loop of {quiet:g} s its "
                                     f"tag's noise moves {parameters[j]} by {fmt(data.jitter(i, j, quiet))} of its "
                                     f"range (standard deviation; limit {data.checks.max_jitter:g})")
        if slowed:
            tau = self.tau if self.tauc is None else recording_time_constants(self.tau, self.tauc)
            self.predicted, _ = data.predict(chosen, tau, speeds)
            for i, (fast, slow) in slowed.items():
                j = chosen[i]
                ratio = self.predicted.get(i, (math.nan, math.nan))[0]
                self.warnings.append(
                    f"pair {variables[i]}/{parameters[j]}: loop slowed from {fast:.0f} s to {slow:.0f} s "
                    f"(its tag's noise would move {parameters[j]} by {fmt(data.jitter(i, j, fast))} of its "
                    f"range, {fmt(data.jitter(i, j, slow))} with the slower loop; limit "
                    f"{data.checks.max_jitter:g}); predicted ratio {fmt(ratio)}")
                logger.info(self.warnings[-1])

    def pairs(self, settings: PairingSettings) -> list[Pair]:
        """The chosen pairs, each with the largest gain any gain set shows (and its time constant)."""
        G, tau, G2, tau2, Gc, tauc, chosen = self.G, self.tau, self.G2, self.tau2, self.Gc, self.tauc, self.chosen
        assert self.lam is not None
        pairs = []
        for i in range(self.m):
            if i not in chosen:
                continue
            j = chosen[i]
            ratio, at_bound = self.predicted.get(i, (math.nan, math.nan))
            gain, t63 = float(G[i, j]), float(tau[i, j])
            if G2 is not None and tau2 is not None and abs(G2[i, j]) > abs(gain):
                gain = float(G2[i, j])
                t63 = float(tau2[i, j]) if math.isfinite(tau2[i, j]) else t63
            if Gc is not None and tauc is not None and abs(Gc[i, j]) > abs(gain):
                gain = float(Gc[i, j])
                t63 = float(tauc[i, j]) if math.isfinite(tauc[i, j]) else t63
            block = self.block
            lam_ij = (block.lambda_of(j) if block is not None and j in block.parameters else float(self.lam[i, j]))
            pairs.append(Pair(self.variables[i], self.parameters[j], lam_ij, gain, t63, ratio, at_bound,
                              closed_loop=self.speeds.get(i, math.nan)))
            if lam_ij > settings.large:
                self.warnings.append(f"pair {self.variables[i]}/{self.parameters[j]} has a large relative gain "
                                     f"{fmt(lam_ij)}")
        if chosen:
            order_i = sorted(chosen)
            self.pairs_cond = condition_number(self.S[np.ix_(order_i, [chosen[i] for i in order_i])])
            limit = (settings.checks or DataChecks()).max_condition if self.data is not None else None
            if limit is not None and self.pairs_cond > limit:
                self.warnings.append(f"the scaled gains of the chosen pairs are ill-conditioned (condition number "
                                     f"{fmt(self.pairs_cond)} > {limit:g}): the loops will fight each other")
        return pairs

    def explain_unpaired_variables(self, settings: PairingSettings) -> None:
        """A reason for every variable still in the choice that got no pair."""
        rows, cols, chosen, data, lam_sub, allowed = (self.rows, self.cols, self.chosen, self.data, self.lam_sub,
                                                      self.allowed)
        variables, parameters, min_lambda = self.variables, self.parameters, settings.min_lambda
        assert lam_sub is not None and allowed is not None
        for a, i in enumerate(rows):
            if i in chosen or i in self.excluded:
                continue
            positive = [(lam_sub[a, b], cols[b]) for b in range(len(cols))
                        if lam_sub[a, b] >= min_lambda and allowed[a, b]]
            rejected = data.rejection(i) if data is not None else None
            if i in self.flipped:
                rejected = self.flipped[i] if rejected is None else f"{self.flipped[i]}; {rejected}"
            if not positive and rejected is not None and 1e-9 < lam_sub[a].max() < min_lambda:
                best = int(np.argmax(lam_sub[a]))
                reason = (f"no parameter has a relative gain of at least {min_lambda:g} with it (largest: "
                          f"{parameters[cols[best]]}, {fmt(lam_sub[a, best])}); {rejected}")
            elif not positive and rejected is not None:
                reason = rejected
            elif not positive and (lam_sub[a] > 1e-9).any():
                best = int(np.argmax(lam_sub[a]))
                reason = (f"no parameter has a relative gain of at least {min_lambda:g} with it (largest: "
                          f"{parameters[cols[best]]}, {fmt(lam_sub[a, best])})")
            elif not positive:
                reason = "no parameter has a positive relative gain with it"
            else:
                best_lam, j = min(positive, key=lambda t: abs(t[0] - 1.0))
                taker = next((variables[v] for v, q in chosen.items() if q == j), None)
                reason = (f"no unused parameter with a positive relative gain is left (best was {parameters[j]}, "
                          f"lambda {fmt(best_lam)}, taken by {taker})" if taker else
                          "fewer usable parameters than variables")
                if rejected is not None:
                    reason = f"{rejected}; {reason}"
            if self.var_unit[i] is not None and self.block_cols:
                reason = unit_tag_reason(i, self.block, self.S, variables, parameters, self.var_unit,
                                          self.par_unit, [cols[b] for b in self.block_cols],
                                          allowed[a, self.block_cols],
                                          data.pair_reason if data is not None else None) + (
                    "" if reason == rejected else f"; among the other parameters: {reason}")
            self.left_out.append((variables[i], reason))

    def explain_unused_parameters(self, settings: PairingSettings) -> None:
        """A reason for every parameter still in the choice that got no variable."""
        rows, cols, chosen, data, lam_sub, allowed = (self.rows, self.cols, self.chosen, self.data, self.lam_sub,
                                                      self.allowed)
        variables, parameters = self.variables, self.parameters
        assert lam_sub is not None and allowed is not None
        used = set(chosen.values())
        for b, j in enumerate(cols):
            if j in used:
                continue
            col = lam_sub[:, b]
            if self.par_unit[j] is not None:
                self.left_out.append((parameters[j], self._unit_parameter_why(b, j, settings)))
                continue
            if self.excluded and len(self.excluded) == len(rows):
                reason = "no tracking variable is worth tracking (see the variables' reasons)"
            elif np.all(col <= 1e-9):
                reason = "no variable has a positive relative gain with it"
            elif data is not None and not (allowed[:, b] & (col > 1e-9)).any():
                dropped = [v for v, q, _ in data.rejected if q == parameters[j] and (v, q) not in data.apart]
                apart = [v for v, q, _ in data.rejected if q == parameters[j] and (v, q) in data.apart]
                served = ", ".join(f"{variables[rows[a]]} (lambda {fmt(col[a])})" for a in np.argsort(-col)
                                   if col[a] > 1e-9)
                reason = (f"the data checks rejected it for every variable it could serve: {served}"
                          + (f"; predicted tracking of {', '.join(dict.fromkeys(dropped))} too poor" if dropped else "")
                          + (f"; on {', '.join(dict.fromkeys(apart))} it cannot be told apart from a candidate left "
                             "unpaired (see their reasons)" if apart else "")
                          + ("" if dropped or apart else
                             "; see their reasons (it cannot close their offsets from inside its bounds, or they "
                             "are at their noise floor)"))
            elif data is not None and best_rejected(col, allowed[:, b]) is not None:
                a_best = best_rejected(col, allowed[:, b])
                reason = (f"the data checks rejected its best pair, with {variables[rows[a_best]]} (lambda "
                          f"{fmt(col[a_best])}): see {variables[rows[a_best]]}")
            elif len(used) >= len(rows) - len(self.excluded):
                best = int(np.argmin(np.where(col > 1e-9, np.abs(col - 1.0), np.inf)))
                reason = (f"not needed: every variable is paired (closest was {variables[rows[best]]}, "
                          f"lambda {fmt(col[best])})")
            else:
                reason = "another parameter gave relative gains closer to 1 for the variables it could serve"
            self.left_out.append((parameters[j], reason))

    def _unit_parameter_why(self, b: int, j: int, settings: PairingSettings) -> str:
        """Why unit parameter *j* (column *b* of the choice) is unpaired, with the separation check's word."""
        rows, chosen, data, block, allowed, S = self.rows, self.chosen, self.data, self.block, self.allowed, self.S
        assert allowed is not None
        own = [rows[a] for a in range(len(rows)) if self.var_unit[rows[a]] == self.par_unit[j]]
        why = unit_parameter_reason(j, own, block, self.variables, self.parameters, self.par_unit, allowed[:, b],
                                     rows, self.excluded, settings.min_lambda)
        if data is not None and block is not None and any(c == j for c, _ in block.dropped):
            # what the separation check would say with it on its strongest usable tag
            free = [i for i in own if i not in chosen and i not in self.excluded and allowed[rows.index(i), b]]
            if free:
                i = max(free, key=lambda r: abs(S[r, j]))
                trial = {**chosen, i: j}
                found = data.entangled(trial, [q for q in self.cols if q not in trial.values()], S)
                if found is not None:
                    why += f"; with it on {self.variables[i]}, {self.variables[found[0]]}: {found[2]}"
        return why

    def pairing(self, pairs: list[Pair], checks: DataChecks | None) -> Pairing:
        """The result, the warnings logged."""
        for msg in self.warnings:
            logger.info(msg)
        assert self.lam is not None
        common = (tuple(pairs), tuple(self.left_out), tuple(self.warnings), self.variables, self.parameters, self.G,
                  self.S, self.lam, self.cond)
        data = self.data
        if data is None:
            return Pairing(*common, pairs_condition_number=self.pairs_cond, block=self.block)
        return Pairing(*common, data.stats, data.reach, data.checks, self.pairs_cond, tuple(data.rejected),
                       block=self.block)


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
                                   f"(lambda {fmt(p.lambda_)}), which the frozen structure pairs with {taker}")
            continue
        added.append(Pair(p.variable, p.parameter, p.lambda_, p.gain, p.time_constant, p.predicted_ratio,
                          p.at_bound, rga_from="recording", closed_loop=p.closed_loop))
    # every pair together, with the recorded gains: drop the worst added pair while it would fail
    data = DataView(G, V, P, residuals, bounds, checks)
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
