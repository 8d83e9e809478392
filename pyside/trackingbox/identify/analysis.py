"""``trackingbox identify``: what the data can determine, before any estimation.

At the start values and at a few points spread inside the bounds
(:func:`~trackingbox.identify.model.inside_points`) the twin's output
sensitivities on the training window are taken (exact, or central differences:
:mod:`trackingbox.identify.model`), scaled (log-parameters where the bounds are
positive, else bound ranges; each tag's rows divided by its sensor noise, read
from the measurements themselves: :func:`tag_noise`) and analysed
(:func:`trackingbox.identify.structure.analyse`): numerical rank, the directions
whose 95 % interval would be wider than half what the bounds allow (with the
sensor noise alone: the best case, as model error only widens them), the
parameters in those directions, and the combinations the data do determine --
products and ratios where the undetermined direction is one in ``ln θ`` at every
point checked, sums where it is one in the parameters' own units, else the
direction's numbers. Where the twin has further outputs nobody measures, the
ones that would see an undetermined direction are named.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..analysis.offsets import HELD_FRACTION, held_fraction, noise_floor, noise_sigma
from ..errors import EstimationError, TrackingError
from ..fmu.info import read_info
from ..simulation.models import close_models
from . import structure as st
from .model import Evaluation, TwinWindow, inside_points, window_for

log = logging.getLogger(__name__)

#: Points inside the bounds checked besides the start values.
DEFAULT_POINTS = 3
#: Largest angle (rad) between the undetermined directions at two points that still counts as "the
#: same direction": 0.1 rad is a 10 % change of the exponents' ratios.
SAME_DIRECTION = 0.1
#: Fraction of the measured range used as a tag's noise when neither the first differences nor the
#: spread around a moving mean give one (a noise-free, e.g. computed, tag).
FALLBACK_NOISE = 1e-3
#: Move along an undetermined direction (in ln θ) the candidate outputs are judged by: 10 %.
PROBE_MOVE = 0.1
#: Two parameters are in one group of undetermined parameters when the undetermined subspace's
#: projection couples them by more than this (of the geometric mean of their own projections).
LINK = 0.1
#: Tags named in a finding's text (the ones carrying most of the group's sensitivity).
TAGS_NAMED = 3

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class Combination:
    """A combination of parameters the data determine: a product/ratio or a sum.

    Attributes
    ----------
    text
        ``R1·C``, ``R1/R2`` or ``R1 + R2``.
    kind
        ``"product"`` (exponents on the parameters) or ``"sum"`` (coefficients).
    terms
        Parameter -> exponent or coefficient (only the non-zero ones).
    """

    text: str
    kind: str
    terms: dict[str, int]

    def value(self, values: Mapping[str, float]) -> float:
        """The combination's value at *values*."""
        if self.kind == "product":
            return float(math.prod(float(values[n]) ** e for n, e in self.terms.items()))
        return float(sum(float(values[n]) * c for n, c in self.terms.items()))

    def to_json(self) -> dict[str, Any]:
        return {"text": self.text, "kind": self.kind, "terms": dict(self.terms)}


@dataclass(frozen=True)
class Finding:
    """One group of parameters the data cannot tell apart.

    Attributes
    ----------
    parameters
        The parameters in the group.
    kind
        ``"product"``, ``"sum"`` or ``"direction"`` (no simple structure).
    undetermined
        The undetermined directions: exponent vectors (products), coefficient vectors in
        the parameters' units (sums), or unit vectors in the scaled coordinates (directions).
    determined
        The combinations the data do determine (empty for ``"direction"``).
    tags
        Tags that carry these parameters' effect (largest share of their sensitivities first).
    structural
        The direction is numerically null (below the rank tolerance) at every point checked.
    consistent
        The same structure was found at every point checked.
    candidates
        Unmeasured twin outputs that would see the direction: ``(variable, change, scale, unit)``:
        its RMS change for a move of :data:`PROBE_MOVE` along the direction, the largest RMS change
        a move of :data:`PROBE_MOVE` of one of its parameters gives, and its unit.
    message
        The finding in plain words.
    """

    parameters: tuple[str, ...]
    kind: str
    undetermined: tuple[tuple[float, ...], ...]
    determined: tuple[Combination, ...]
    tags: tuple[str, ...]
    structural: bool
    consistent: bool
    candidates: tuple[tuple[str, float, float, str], ...] = ()
    message: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"parameters": list(self.parameters), "kind": self.kind,
                "undetermined": [list(v) for v in self.undetermined],
                "determined": [c.to_json() for c in self.determined], "tags": list(self.tags),
                "structural": self.structural, "consistent": self.consistent,
                "candidates": [{"variable": v, "change": c, "scale": s, "unit": u} for v, c, s, u in self.candidates],
                "message": self.message}


@dataclass(frozen=True)
class PointResult:
    """The structure at one point: where, the singular values, rank, determined directions."""

    label: str
    x: dict[str, float]
    singular_values: tuple[float, ...]
    rank: int
    determined: int
    undetermined_parameters: tuple[str, ...]
    error: str = ""

    def to_json(self) -> dict[str, Any]:
        return {"label": self.label, "x": dict(self.x), "singular_values": list(self.singular_values),
                "rank": self.rank, "determined": self.determined,
                "undetermined_parameters": list(self.undetermined_parameters),
                **({"error": self.error} if self.error else {})}


@dataclass(frozen=True)
class Identifiability:
    """What :func:`identify` found.

    Attributes
    ----------
    names
        The spec's ``[[parameters]]``.
    scaling
        Per parameter ``"log"`` or ``"range"`` (see :mod:`trackingbox.identify.structure`).
    noise
        Tag -> (standard deviation used to scale its rows, where it came from).
    points
        The structure at the start values and at each point inside the bounds.
    rank
        Numerical rank at the start values (of ``len(names)``).
    determined
        Per parameter: determined on its own at the start values.
    findings
        The groups of parameters the data cannot tell apart, with the combinations they do determine.
    correlation
        Correlation matrix of the (scaled) parameters at the start values.
    half_widths
        Per parameter its own 95 % half-width at the start values (scaled units: relative for
        log-scaled parameters, parts of the bound range otherwise; sensor noise only).
    sensitivities
        ``"exact"`` or ``"fd"``, and why not exact.
    runs
        Twin runs made.
    matrix, widths
        The scaled sensitivity matrix at the start values and the bound box's widths (for
        :func:`leave_out`; not in :meth:`to_json`).
    """

    names: tuple[str, ...]
    scaling: tuple[str, ...]
    noise: dict[str, tuple[float, str]]
    points: tuple[PointResult, ...]
    rank: int
    determined: dict[str, bool]
    findings: tuple[Finding, ...]
    correlation: np.ndarray = field(repr=False, compare=False)
    half_widths: dict[str, float] = field(default_factory=dict)
    sensitivities: tuple[str, str] = ("", "")
    runs: int = 0
    matrix: np.ndarray | None = field(default=None, repr=False, compare=False)
    widths: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def complete(self) -> bool:
        """Every parameter determined on its own."""
        return all(self.determined.values())

    def messages(self) -> list[str]:
        """The findings in plain words, and parameters undetermined on their own outside any finding."""
        out = [f.message for f in self.findings]
        grouped = {p for f in self.findings for p in f.parameters}
        for name, ok in self.determined.items():
            if not ok and name not in grouped:
                hw = self.half_widths.get(name, math.inf)
                k = self.names.index(name)
                what = (f"±{_pct(hw)}" if self.scaling[k] == "log" else f"±{hw:.3g} of its bound range")
                out.append(f"{name} is not determined: with the sensor noise alone its 95 % interval would be "
                           f"{what}, more than half of what its bounds allow")
        return out

    def to_json(self) -> dict[str, Any]:
        return {
            "parameters": list(self.names), "scaling": list(self.scaling),
            "rows": "each tag's samples divided by its noise standard deviation",
            "noise": {t: {"sigma": s, "source": src} for t, (s, src) in self.noise.items()},
            "rank": self.rank, "of": len(self.names),
            "determined": dict(self.determined),
            "half_widths": {k: _json_float(v) for k, v in self.half_widths.items()},
            "findings": [f.to_json() for f in self.findings],
            "messages": self.messages(),
            "correlation": [[_json_float(v) for v in row] for row in np.asarray(self.correlation)],
            "points": [p.to_json() for p in self.points],
            "sensitivities": {"method": self.sensitivities[0], "reason": self.sensitivities[1]},
            "runs": self.runs,
        }


def _json_float(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _pct(relative_half_width: float) -> str:
    """A half-width in ln-units as a percentage (``exp(h) - 1``)."""
    if not math.isfinite(relative_half_width):
        return "unbounded"
    return f"{100.0 * math.expm1(relative_half_width):.3g} %"


# --------------------------------------------------------------------------- noise of the tags


def tag_noise(window: Any, interval: float, outputs: Sequence[str]) -> dict[str, tuple[float, str]]:
    """Each output tag's sensor noise on *window*, read from its measurements.

    :func:`~trackingbox.analysis.offsets.noise_sigma` (the robust spread of the first
    differences); for a held (exception-reported) tag, whose differences are mostly zero,
    :func:`~trackingbox.analysis.offsets.noise_floor` (the spread around a 30 min moving
    mean); else :data:`FALLBACK_NOISE` of the measured range.
    """
    out: dict[str, tuple[float, str]] = {}
    for tag in outputs:
        y = np.asarray(window.measured[tag], dtype=float)
        sigma, source = noise_sigma(y), "first differences of the measurement"
        if not (sigma > 0) or held_fraction(y) > HELD_FRACTION:
            floor = noise_floor(y, interval)
            if floor > 0:
                sigma, source = floor, "spread around its 30 min moving mean (a held tag)"
        if not (sigma > 0 and math.isfinite(sigma)):
            ok = y[np.isfinite(y)]
            span = float(ok.max() - ok.min()) if ok.size else 1.0
            sigma, source = FALLBACK_NOISE * (span if span > 0 else 1.0), f"{FALLBACK_NOISE:g} of its range"
        out[tag] = (float(sigma), source)
    return out


# --------------------------------------------------------------------------- the analysis


def identify(spec: Any, *, points: int = DEFAULT_POINTS, method: str = "auto", warmup: float | None = None,
             candidates: bool = True, progress: Progress | None = None, x: Sequence[float] | None = None,
             fraction: float = st.DETERMINED_FRACTION) -> Identifiability:
    """What the training window can determine of the spec's ``[[parameters]]`` (see the module docstring).

    Parameters
    ----------
    spec
        A loaded spec.
    points
        Points inside the bounds checked besides the start values (0: the start only).
    method
        Sensitivities: ``"auto"`` (exact where the twin provides directional derivatives,
        else central differences), ``"exact"`` or ``"fd"``.
    warmup
        The estimation's warm-up (s).
    candidates
        Look for unmeasured twin outputs that would see an undetermined direction.
    progress
        ``progress(stage, done, total)``.
    x
        The first point instead of the start values.
    fraction
        :data:`~trackingbox.identify.structure.DETERMINED_FRACTION`.
    """
    if not (isinstance(points, int) and points >= 0):
        raise EstimationError(f"identify: points must be an integer >= 0, not {points!r}")
    try:
        problem, window = window_for(spec, warmup=warmup)
        tw = TwinWindow(problem, window, method)  # type: ignore[arg-type]
        noise = tag_noise(window, problem.sample_time, list(problem.outputs))
        x0 = np.asarray(problem.start if x is None else x, dtype=float)
        xs = [("start values" if x is None else "given point", x0)]
        xs += [(f"point {i + 1} inside the bounds", p)
               for i, p in enumerate(inside_points(x0, problem.lower, problem.upper, points))]
        results: list[PointResult] = []
        structures: list[tuple[np.ndarray, st.Structure, st.Scaling] | None] = []
        matrices: list[np.ndarray] = []
        first: Evaluation | None = None
        for i, (label, xi) in enumerate(xs):
            if progress is not None:
                progress("sensitivities", i, len(xs))
            try:
                ev = tw.sensitivities(xi)
            except TrackingError as exc:
                if i == 0:
                    raise EstimationError(f"identify: the twin failed at the {label} ({exc})") from exc
                results.append(PointResult(label, dict(zip(problem.names, map(float, xi))), (), 0, 0, (), str(exc)))
                structures.append(None)
                continue
            first = ev if i == 0 else first
            structure, scaling = point_structure(ev, problem, noise, fraction=fraction)
            structures.append((xi, structure, scaling))
            matrices.append(_scaled(ev, scaling, noise))
            undet = tuple(n for n, p in zip(problem.names, structure.participation()) if p > st.PARTICIPATION)
            results.append(PointResult(label, dict(zip(problem.names, map(float, xi))),
                                       tuple(float(s) for s in structure.singular_values), structure.rank,
                                       int(structure.determined.sum()), undet))
        if progress is not None:
            progress("sensitivities", len(xs), len(xs))
        assert first is not None and structures[0] is not None
        x_start, s0, scaling0 = structures[0]
        others = [(xi, s, sc) for item in structures[1:] if item is not None for xi, s, sc in [item]]
        findings = name_findings(s0, scaling0, x_start, others, first, list(problem.names))
        if candidates and findings:
            findings = [replace(f, candidates=_candidates(tw, problem, x_start, scaling0, f)) for f in findings]
        findings = [replace(f, message=finding_text(f)) for f in findings]
        marginal_ok = s0.marginal <= fraction * scaling0.widths
        grouped = {p for f in findings for p in f.parameters}
        determined = {n: bool(ok) and n not in grouped for n, ok in zip(problem.names, marginal_ok)}
        return Identifiability(
            names=tuple(problem.names), scaling=scaling0.kinds, noise=noise, points=tuple(results),
            rank=s0.rank, determined=determined, findings=tuple(findings), correlation=s0.correlation,
            half_widths={n: float(h) for n, h in zip(problem.names, s0.marginal)},
            sensitivities=(tw.method, tw.reason), runs=tw.runs, matrix=matrices[0], widths=scaling0.widths)
    finally:
        close_models()


def point_structure(ev: Evaluation, problem: Any, noise: Mapping[str, tuple[float, str]], *,
                    covariance: np.ndarray | None = None,
                    fraction: float = st.DETERMINED_FRACTION) -> tuple[st.Structure, st.Scaling]:
    """The :class:`~trackingbox.identify.structure.Structure` of one evaluation, rows scaled by *noise*."""
    scaling = st.parameter_scaling(ev.x, problem.lower, problem.upper)
    S = _scaled(ev, scaling, noise)
    return st.analyse(S, list(problem.names), scaling.widths, covariance=covariance, fraction=fraction), scaling


def _scaled(ev: Evaluation, scaling: st.Scaling, noise: Mapping[str, tuple[float, str]]) -> np.ndarray:
    assert ev.jacobian is not None
    rows = [ev.jacobian[tag] for tag in ev.simulated]
    sig = [np.full(len(ev.simulated[tag]), noise[tag][0]) for tag in ev.simulated]
    return st.scale_matrix(np.concatenate(rows, axis=0), scaling, np.concatenate(sig))


def name_findings(s0: st.Structure, scaling: st.Scaling, x0: np.ndarray,
                  others: Sequence[tuple[np.ndarray, st.Structure, st.Scaling]], ev: Evaluation,
                  names: list[str]) -> list[Finding]:
    """Group the undetermined subspace of *s0* by parameters and name each group (module docstring).

    The subspace's basis is brought to reduced row echelon form; parameters that share a
    row form a group, and each group's rows are its own undetermined directions.
    """
    groups = _groups(s0.undetermined, len(names))
    return [_name_group(members, Ug, s0, scaling, x0, others, ev, names) for members, Ug in groups]


def _groups(U: np.ndarray, n: int) -> list[tuple[list[int], np.ndarray]]:
    """``(members, orthonormal basis on the members)`` for each group of the subspace span(U) of R^n.

    The projection ``P = U Uᵀ`` does not depend on the basis; parameters ``i`` and ``j`` are
    in one group when ``|P_ij|`` is more than :data:`LINK` of ``sqrt(P_ii P_jj)`` (the subspace
    couples them), and a group's directions are the part of the subspace on its members.
    """
    if U.size == 0:
        return []
    P = U @ U.T
    diag = np.sqrt(np.clip(np.diag(P), 0.0, None))
    involved = [j for j in range(n) if diag[j] > st.PARTICIPATION]
    parent = {j: j for j in involved}

    def find(a: int) -> int:
        while parent[a] != a:
            a = parent[a]
        return a

    for i in involved:
        for j in involved:
            if i < j and abs(P[i, j]) > LINK * diag[i] * diag[j]:
                parent[find(j)] = find(i)
    groups: dict[int, list[int]] = {}
    for j in involved:
        groups.setdefault(find(j), []).append(j)
    out = []
    for members in groups.values():
        members = sorted(members)
        q, sv, _ = np.linalg.svd(U[members], full_matrices=False)
        out.append((members, q[:, sv > 0.5]))
    return sorted(out, key=lambda g: g[0])


def _group_subspace(structure: st.Structure, members: list[int]) -> np.ndarray:
    """The undetermined directions of *structure* that live on exactly *members* (empty if none do)."""
    for found, Ug in _groups(structure.undetermined, len(structure.names)):
        if found == members:
            return Ug
    return np.zeros((len(members), 0))


def _name_group(members: list[int], Ug: np.ndarray, s0: st.Structure, scaling: st.Scaling, x0: np.ndarray,
                others: Sequence[tuple[np.ndarray, st.Structure, st.Scaling]], ev: Evaluation,
                names: list[str]) -> Finding:
    params = tuple(names[j] for j in members)
    k = Ug.shape[1]
    # structural: this group's directions are numerically null at the start and at every other point
    zero = s0.half_widths == math.inf
    structural = bool(zero.any()) and _within(Ug, s0.directions[members][:, zero])
    for _, s, _sc in others:
        z = s.half_widths == math.inf
        structural = structural and bool(z.any()) and _within(Ug, s.directions[members][:, z])
    tags = _carrying_tags(ev, members, scaling)
    all_log = all(scaling.kinds[j] == "log" for j in members)
    if all_log:
        rational = st.rational_basis(Ug)
        comps = st.complement_combinations(rational, len(members)) if rational is not None else []
        if rational is not None and len(comps) == len(members) - len(rational) \
                and _same_everywhere(rational, members, others, log=True):
            return Finding(params, "product", tuple(tuple(float(v) for v in q) for q in rational),
                           tuple(Combination(st.product_text(a, params), "product",
                                             {p: int(e) for p, e in zip(params, a) if e}) for a in comps),
                           tags, structural, True)
    lin = st.to_linear(Ug if Ug.ndim == 2 else Ug[:, None], x0, _sub_scaling(scaling, members))
    rational = st.rational_basis(lin)
    comps = st.complement_combinations(rational, len(members)) if rational is not None else []
    if rational is not None and len(comps) == len(members) - len(rational) \
            and _same_everywhere(rational, members, others, log=False):
        return Finding(params, "sum", tuple(tuple(float(v) for v in q) for q in rational),
                       tuple(Combination(st.sum_text(a, params), "sum", {p: int(c) for p, c in zip(params, a) if c})
                             for a in comps), tags, structural, True)
    consistent = all(st.subspace_angle(Ug, _group_subspace(s, members)) <= SAME_DIRECTION for _, s, _ in others)
    dirs = tuple(tuple(round(float(v), 4) for v in Ug[:, i]) for i in range(k))
    return Finding(params, "direction", dirs, (), tags, structural, consistent)


def _sub_scaling(scaling: st.Scaling, members: list[int]) -> st.Scaling:
    return st.Scaling(tuple(scaling.kinds[j] for j in members), scaling.factors[members], scaling.widths[members])


def _within(Ug: np.ndarray, null: np.ndarray) -> bool:
    """Every column of *Ug* lies (within 0.1 rad) in the span of *null*'s columns."""
    if null.size == 0:
        return False
    q, _ = np.linalg.qr(null)
    resid = Ug - q @ (q.T @ Ug)
    return bool(np.linalg.norm(resid, axis=0).max() < math.sin(SAME_DIRECTION))


def _same_everywhere(rational: list[list[int]], members: list[int],
                     others: Sequence[tuple[np.ndarray, st.Structure, st.Scaling]], *, log: bool) -> bool:
    """The rational directions span the group's undetermined subspace at every other point too."""
    R = np.array(rational, dtype=float).T
    for xi, s, sc in others:
        Ui = _group_subspace(s, members)
        if not log:
            Ui = st.to_linear(Ui, xi, _sub_scaling(sc, members)) if Ui.size else Ui
        if Ui.shape[1] != R.shape[1] or st.subspace_angle(R, Ui) > SAME_DIRECTION:
            return False
    return True


def _carrying_tags(ev: Evaluation, members: list[int], scaling: st.Scaling) -> tuple[str, ...]:
    """Tags ordered by their share of the group's (scaled) sensitivity; those below 5 % of the top left out."""
    assert ev.jacobian is not None
    share = {}
    for tag, J in ev.jacobian.items():
        y = ev.measured[tag]
        span = float(np.nanmax(y) - np.nanmin(y)) if y.size else 1.0
        share[tag] = float(np.sqrt(np.mean((J[:, members] * scaling.factors[members]) ** 2)) / (span or 1.0))
    top = max(share.values(), default=0.0)
    return tuple(t for t, v in sorted(share.items(), key=lambda kv: -kv[1]) if top > 0 and v >= 0.05 * top)


def _candidates(tw: TwinWindow, problem: Any, x0: np.ndarray, scaling: st.Scaling,
                finding: Finding) -> tuple[tuple[str, float, float, str], ...]:
    """Unmeasured twin outputs that would see the finding's first undetermined direction, best first."""
    info = read_info(problem.twin)
    measured = set(problem.outputs.values())
    units = {v.name: v.unit or "" for v in info.variables}
    names = [v.name for v in info.variables if v.causality == "output" and v.name not in measured
             and str(v.type).lower() in ("real", "float64", "float32")][:50]
    if not names or not finding.undetermined:
        return ()
    members = [list(problem.names).index(p) for p in finding.parameters]
    q = np.asarray(finding.undetermined[0], dtype=float)
    if finding.kind == "sum":  # coefficients in the parameters' own units -> scaled coordinates
        q = q / scaling.factors[members]
    direction = np.zeros(len(problem.names))
    direction[members] = q / (np.linalg.norm(q) or 1.0)
    try:
        ev = tw.sensitivities(x0, extra=names)
    except TrackingError as exc:
        log.info("no candidate outputs: the twin failed with its further outputs (%s)", exc)
        return ()
    out = []
    for n, (_, J) in ev.extra.items():
        Jz = J * scaling.factors[None, :]
        change = float(np.sqrt(np.mean((Jz @ direction * PROBE_MOVE) ** 2)))
        scale = float(max(np.sqrt(np.mean((Jz[:, j] * PROBE_MOVE) ** 2)) for j in range(Jz.shape[1])))
        if scale > 0 and change > 0.05 * scale:
            out.append((n, change, scale, units.get(n, "")))
    out.sort(key=lambda c: -c[1] / c[2])
    return tuple(out[:3])


def leave_out(found: Identifiability, fraction: float = st.DETERMINED_FRACTION) -> dict[str, str]:
    """Which candidates pairing leaves out, and why (name -> reason): the dynamic analogue of its
    steady-state rank test.

    The candidates are taken strongest first (the norm of their scaled sensitivity column); one
    whose effect on the tags cannot be told from that of a candidate kept before it -- with only
    the two of them free, a direction between them is not determined (:func:`~trackingbox.identify.
    structure.analyse` of the two columns) -- is left out, naming that candidate; so is one the
    data do not determine even alone. Directions that need three or more parameters (``R1``,
    ``R2`` and ``C`` of a wall: any two of them are told apart once the third is held) are
    reported by ``identify`` and ``estimate`` but leave no candidate out: the loops track only
    the parameters paired, the others held.
    """
    if found.matrix is None or found.widths is None:
        return {}
    names = list(found.names)
    S, w = found.matrix, found.widths
    norms = np.linalg.norm(S, axis=0)
    order = [int(j) for j in np.argsort(-norms, kind="stable")]
    kept: list[int] = []
    out: dict[str, str] = {}
    for j in order:
        alone = st.analyse(S[:, [j]], [names[j]], w[[j]], fraction=fraction)
        if not alone.determined.all():
            out[names[j]] = ("the data do not see it: with the sensor noise alone its 95 % interval would span more "
                             "than half its bounds (the twin's output sensitivities over the training window, "
                             "trackingbox identify)")
            continue
        twin = next((k for k in kept if not st.analyse(S[:, [k, j]], [names[k], names[j]], w[[k, j]],
                                                        fraction=fraction).determined.all()), None)
        if twin is None:
            kept.append(j)
            continue
        pair = st.analyse(S[:, [twin, j]], [names[twin], names[j]], w[[twin, j]], fraction=fraction)
        v = pair.undetermined[:, 0]
        v = v if v[0] > 0 else -v
        direction = ", ".join(f"{x:+.2f} ln {n}" if found.scaling[k] == "log" else f"{x:+.2f} {n}/range"
                              for x, n, k in zip(v, (names[twin], names[j]), (twin, j)))
        out[names[j]] = (f"its effect on the tags cannot be told from that of {names[twin]}: with the two free, "
                         f"the direction ({direction}) is not determined over the training window (the twin's "
                         f"output sensitivities, trackingbox identify); {names[twin]} has the larger effect")
    return out


# --------------------------------------------------------------------------- words


def finding_text(f: Finding) -> str:
    """One finding in plain words."""
    who = st.listing(list(f.parameters))
    tags = list(f.tags[:TAGS_NAMED]) + (["others"] if len(f.tags) > TAGS_NAMED else [])
    on = f" on {st.listing(tags)}" if f.tags else ""
    if f.kind == "product":
        if len(f.undetermined) == 1:
            q = [int(round(e)) for e in f.undetermined[0]]
            if len({abs(e) for e in q if e}) == 1:
                up = [p for p, e in zip(f.parameters, q) if e > 0]
                down = [p for p, e in zip(f.parameters, q) if e < 0]
                move = f"multiplying {st.listing(up)} by any factor f" + (
                    f" and dividing {st.listing(down)} by it" if down else "")
            else:
                moves = [f"{'multiplying' if e > 0 else 'dividing'} {p} by f{_power(abs(e))}"
                         for p, e in zip(f.parameters, q) if e]
                move = st.listing(moves) + " for any factor f"
            head = f"{who} cannot be told apart{on}: {move} leaves {'them' if f.tags else 'the outputs'} unchanged"
        else:
            head = f"{who} cannot be told apart{on} ({len(f.undetermined)} undetermined directions)"
        tail = (f"; only {st.listing([c.text for c in f.determined])} "
                f"{'is' if len(f.determined) == 1 else 'are'} determined" if f.determined else
                "; none of them is determined")
    elif f.kind == "sum":
        if len(f.undetermined) == 1:
            q = f.undetermined[0]
            up = [p for p, c in zip(f.parameters, q) if c > 0]
            down = [p for p, c in zip(f.parameters, q) if c < 0]
            move = f"raising {st.listing(up)} and lowering {st.listing(down)} by matching amounts" if down else \
                f"moving {st.listing(up)} together"
            head = f"{who} cannot be told apart{on}: {move} leaves the outputs unchanged"
        else:
            head = f"{who} cannot be told apart{on}"
        tail = (f"; only {st.listing([c.text for c in f.determined])} "
                f"{'is' if len(f.determined) == 1 else 'are'} determined" if f.determined else "")
    else:
        q = np.asarray(f.undetermined[0] if f.undetermined else (), dtype=float)
        if q.size and q[np.argmax(np.abs(q))] < 0:
            q = -q
        terms = ", ".join(f"{v:+.2f} ln {p}" for p, v in zip(f.parameters, q) if abs(v) >= 0.05)
        head = f"{who} cannot be told apart{on}: moving them along ({terms}) leaves the outputs unchanged"
        tail = ("" if len(f.undetermined) <= 1 else f" ({len(f.undetermined)} such directions)") + (
            "; it is the same direction at every point checked" if f.consistent else
            "; the direction turns across the bounds (neither a product nor a sum of them is determined)")
    text = head + tail
    if f.structural:
        text += "; at every point checked, whatever the noise"
    fix = _fix_text(f)
    return f"{text}. {fix}" if fix else text + "."


def _power(e: float) -> str:
    e = int(round(e))
    return "" if e == 1 else str(e).translate(str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻"))


def _fix_text(f: Finding) -> str:
    k = len(f.undetermined)
    n = len(f.parameters)
    holds = "one of them" if k == 1 and n > 1 else f"{k} of them"
    parts = [f"Fix {holds} ([fixed] in the spec) or measure what separates them"] if n > 1 else \
        [f"Fix {f.parameters[0]} ([fixed]) or measure what it acts on"]
    if f.candidates:
        v, change, scale, unit = f.candidates[0]
        u = f" {unit}" if unit else ""
        parts.append(f"the twin's {v} would see it (a {PROBE_MOVE:.0%} move along the undetermined direction "
                     f"changes it by {change:.3g}{u} RMS, against at most {scale:.3g}{u} for a {PROBE_MOVE:.0%} "
                     "move of one parameter)")
    return ": ".join(parts) + "."
