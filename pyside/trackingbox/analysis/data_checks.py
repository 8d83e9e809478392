"""The pairing's data checks: what the untracked run beside the measurements says about each pair
(:class:`DataView`: noise floor, reach, predicted tracking, separation, loop noise; :func:`leakage`).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from ..errors import AnalysisError
from .offsets import Residuals, loop_jitter, predict_tracking, reach
from .pairing_model import (
    IDENTIFY_FLOOR,
    IDENTIFY_MOVE,
    SEPARATION_MOVE,
    SETTLE_LOOPS,
    DataChecks,
    fmt,
)

logger = logging.getLogger(__name__)

def best_rejected(col: np.ndarray, allowed: np.ndarray) -> int | None:
    """Row of the positive relative gain closest to 1 in *col* if the data checks forbade it, else None."""
    score = np.where(col > 1e-9, np.abs(col - 1.0), np.inf)
    if not np.isfinite(score).any():
        return None
    a = int(np.argmin(score))
    return None if allowed[a] else a


class DataView:
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
                    f"({fmt(structure[i, j])}) and the other with the twin run as the data were recorded "
                    f"({fmt(G[i, j])}): a loop on it would act the wrong way")
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
                          f"{fmt(self.full_move(i, j) * IDENTIFY_MOVE)}"
                          for j in named)
        return (f"its noise floor {fmt(st.noise)} is {100 * self.floor_ratio[i]:.0f} % of its untracked RMS error, "
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
                  f"{self.parameters[j]} by {fmt(float(L[a, b]))} of its own (limit {limit:g}"
                  + (f"; the data allow {self.parameters[k]} a move of {fmt(self.moved_at_most(k))} of its range, "
                     f"so the limit applies to {fmt(float(L[a, b] * weight[b]))}" if weight[b] < 1.0 else "")
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
                return (f"its noise floor {fmt(st.noise)} (estimated from the data) is {100 * f:.0f} % of its "
                        f"untracked RMS error once loops of {c.closed_loop:g} s settled: no loop brings it under "
                        f"{100 * c.max_floor:.0f} %")
        elif st.noise_ratio < c.noise_ratio:
            return (f"its untracked error is at noise level: RMS {fmt(st.rms)} (mean {fmt(st.mean)}) is "
                    f"below {c.noise_ratio:g} x the sensor noise {fmt(st.noise)} estimated from the data "
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
                f"{self.parameters[j]} moves {self.variables[i]} by {fmt(self.moves[i, j])} toward the "
                f"measurement, the offset is {fmt(st.mean)} (mean of measured - untracked; needs "
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
            return (f"the remaining range of {self.parameters[j]} moves it by only {fmt(self.moves[i, j])} toward "
                    f"the measurement, the offset is {fmt(st.mean)}")
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
        return (f"the remaining range of {self.parameters[j]} moves it by only {fmt(self.moves[i, j])} "
                f"toward the measurement, the offset is {fmt(st.mean)}")


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
