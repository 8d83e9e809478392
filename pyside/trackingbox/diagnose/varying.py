"""Candidates the twin tracks in time (a fouling resistance), as the null model lets them move.

A tracking simulator follows a fouling resistance as it grows: that change is the twin's
own job, not a missing effect. The null model of the diagnosis therefore lets the spec's
``[diagnose] varying`` candidates move in time the way tracking would, and every
candidate effect is judged against that null, never against one that holds them
constant (on the evaporator, whose plant fouls by 2e-4 m2.K/W over the record, a
constant fouling left a trend of 740 Pa in the pump's discharge pressure PI-6152 that
``sensor-drift`` then explained).

How: piecewise linear in time with knots every :attr:`VaryingBasis.step` seconds (the
tracking loops' closed-loop time constant: what a tracked parameter can follow), and
quasi-static: the outputs move by their sensitivity to a constant change of the
parameter (the null model's output Jacobian column) times the change at that time (a
fouling changes over hours, the twin settles in minutes). Linear in the knots'
increments, so every least-squares fit of the diagnosis (the null's polish, each
candidate's joint fit, the levelling of a fitted candidate) carries them as extra
columns:

* on the training window the increments after the first knot (the constant level is
  the candidate's own column), with their sign fixed by the kind: ``rising`` (a
  fouling: deposits build up between cleanings, they do not wash off), ``falling``
  or ``free``;
* on the validation window, after the constants (and the effect) fitted on training
  are applied, the level and the increments again, fitted on validation: the twin
  tracks the parameter there too, and the held-out test is then about what tracking
  cannot do.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

#: Knot spacing (s) when the spec's ``[pairing] closed_loop`` does not give one.
DEFAULT_STEP = 3 * 3600.0

#: Kinds of a varying candidate and the sign of its increments (+1: >= 0, -1: <= 0, 0: free).
SIGNS = {"rising": 1, "falling": -1, "free": 0}


def ramps(time: npt.ArrayLike, step: float) -> np.ndarray:
    """``(n, K)`` ramp-steps on *time*: column ``j`` rises from 0 at ``t0 + j step`` to 1 at ``t0 + (j+1) step``.

    Their sum with non-negative weights is any non-decreasing piecewise-linear function with
    knots every *step* s from the first time ``t0``, starting at 0.

    >>> ramps([0.0, 5.0, 10.0, 15.0, 20.0], 10.0).tolist()
    [[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.0, 0.5], [1.0, 1.0]]
    """
    t = np.asarray(time, dtype=float)
    if t.size == 0:
        return np.zeros((0, 0))
    t0 = float(t[0])
    k = max(1, int(math.ceil((float(t[-1]) - t0) / step - 1e-9)))
    knots = t0 + step * np.arange(k)
    return np.clip((t[:, None] - knots[None, :]) / step, 0.0, 1.0)


@dataclass(frozen=True)
class VaryingBasis:
    """The time basis of the null model's varying candidates on both windows.

    Attributes
    ----------
    names, kinds
        The varying candidates and their kinds (:data:`SIGNS`).
    index
        Their positions among the problem's candidates (the Jacobian's columns).
    step
        Knot spacing (s).
    train, valid
        :func:`ramps` on each window's grid.
    ranges
        Each candidate's bound range (``upper - lower``): the most an increment may move it.
    lower, upper
        Each candidate's bounds (the validation level stays inside them).
    """

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    index: tuple[int, ...]
    step: float
    train: np.ndarray
    valid: np.ndarray
    ranges: tuple[float, ...]
    lower: tuple[float, ...] = ()
    upper: tuple[float, ...] = ()

    @property
    def size(self) -> int:
        """Columns on training (increments of every varying candidate)."""
        return len(self.index) * self.train.shape[1]

    def columns(self, jac: Mapping[str, np.ndarray], which: str, tags: Sequence[str], n: Mapping[str, int],
                ) -> dict[str, np.ndarray]:
        """Tag -> columns on window *which* (``"train"``: increments; ``"valid"``: level and increments).

        *jac*: tag -> ``(n, p)`` output sensitivity to the candidates on that window.
        """
        basis = self.train if which == "train" else self.valid
        out = {}
        for tag in tags:
            j = jac.get(tag)
            blocks = []
            for i in self.index:
                col = j[:, i:i + 1] if j is not None and j.shape[1] > i else np.zeros((n[tag], 1))
                if which == "valid":
                    blocks.append(col)
                blocks.append(col * basis)
            out[tag] = np.hstack(blocks) if blocks else np.zeros((n[tag], 0))
        return out

    def bounds(self, which: str, x: npt.ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the coefficients of :meth:`columns`: the increments' signs, at most a bound range each;
        on validation the level first, a move from *x* (the candidates' values) within their bounds."""
        lo: list[float] = []
        hi: list[float] = []
        k = (self.train if which == "train" else self.valid).shape[1]
        xs = np.asarray(x, dtype=float) if x is not None else None
        for pos, (i, kind, span) in enumerate(zip(self.index, self.kinds, self.ranges)):
            if which == "valid":
                if xs is not None and self.lower and self.upper:
                    lo.append(self.lower[pos] - float(xs[i]))
                    hi.append(self.upper[pos] - float(xs[i]))
                else:
                    lo.append(-math.inf)
                    hi.append(math.inf)
            sign = SIGNS[kind]
            lo += [0.0 if sign > 0 else -span] * k
            hi += [0.0 if sign < 0 else span] * k
        return np.array(lo), np.array(hi)

    def to_json(self) -> dict[str, Any]:
        return {"parameters": dict(zip(self.names, self.kinds)), "step": float(self.step),
                "knots": {"training": int(self.train.shape[1]), "validation": int(self.valid.shape[1])}}


def basis_for(spec: Any, problem: Any, train_time: npt.ArrayLike, valid_time: npt.ArrayLike,
              step: float | None = None) -> VaryingBasis | None:
    """The :class:`VaryingBasis` of the spec's ``[diagnose] varying`` (None when it names none).

    *step*: knot spacing (s); default the spec's ``[pairing] closed_loop`` (the tracking
    loops' closed-loop time constant), else :data:`DEFAULT_STEP`.
    """
    table = getattr(getattr(spec, "diagnose", None), "varying", ()) or ()
    names = list(problem.names)
    chosen = [(n, k) for n, k in table if n in names]
    if not chosen:
        return None
    if step is None:
        loop = getattr(getattr(spec, "pairing", None), "closed_loop", None)
        step = float(loop) if loop else DEFAULT_STEP
    index = tuple(names.index(n) for n, _ in chosen)
    lower = np.asarray(problem.lower, dtype=float)
    upper = np.asarray(problem.upper, dtype=float)
    return VaryingBasis(tuple(n for n, _ in chosen), tuple(k for _, k in chosen), index, float(step),
                        ramps(train_time, step), ramps(valid_time, step),
                        tuple(float(upper[i] - lower[i]) for i in index),
                        tuple(float(lower[i]) for i in index), tuple(float(upper[i]) for i in index))


def trajectory(basis: VaryingBasis, coef: npt.ArrayLike, which: str, base: npt.ArrayLike) -> dict[str, np.ndarray]:
    """Each varying candidate's value over window *which* from the coefficients of :meth:`VaryingBasis.columns`
    (*base*: the candidates' values the columns are added to)."""
    c = np.asarray(coef, dtype=float)
    b = np.asarray(base, dtype=float)
    grid = basis.train if which == "train" else basis.valid
    k = grid.shape[1]
    out, pos = {}, 0
    for name, i in zip(basis.names, basis.index):
        level = 0.0
        if which == "valid":
            level = float(c[pos])
            pos += 1
        out[name] = b[i] + level + grid @ c[pos:pos + k]
        pos += k
    return out
