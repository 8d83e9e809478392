"""The fixed part of the tracked parameters' bands, computed at track start (part 4 of :mod:`.bands`).

A parameter the twin holds at an estimate -- a ``[fixed]`` value with a
``[fixed_intervals]`` entry, or a ``[[parameters]]`` entry with an ``interval``
that no pair tracks -- is off by up to its interval, and each loop makes its own
parameter absorb what that does to its tag. :func:`held_parts` measures it on
the twin as ``pair`` measures its gains: step tests with the spec's
``[pairing] freeze``, its ``[[states]]`` compensated, at the operating point of
the first hour of the training window (:func:`trackingbox.analysis.steptest.operating_point`),
every parameter at its spec value; each held parameter is stepped once to each
end of its interval and the paired tags' settled change ``Δy`` read against the
unstepped run. The truth of a pair's parameter then lies ``-Δy/gain`` from the
tracked value (``gain`` the pair's, the one its controller is tuned with):
:class:`~.bands.Fixed` per pair, which :class:`~.bands.BandTracker` adds in
quadrature.

With several pairs the loops settle together: each drives its own tag to the
measurement, so a held parameter's effect ``Δy_h`` on all the paired tags is
absorbed jointly, ``Δθ_t = -G_tt⁻¹ Δy_h`` (:func:`joint_shifts`), ``G_tt`` the
tracked parameters' steady gains on their paired tags (tag ``i`` of pair ``i``
against parameter ``j`` of pair ``j``), measured by the same step tests: each
tracked parameter stepped by ``±STEP`` of its bounds' range (clipped to them; the
secant). A held parameter that moves only one tag then shifts every tracked
parameter whose tag that one's offset moves in turn. For one pair this is
``-Δy/gain``, and the pair's own gain is kept there (no extra step tests: the
bands are what they were). Where ``G_tt`` is singular the pairs' own gains are
used and the note says so.

Measured on the evaporator's default plant after one round of ``diagnose --apply``
(72 h, seed 1; :func:`measure` on the re-track's spec with its estimate's intervals): the fouling ``effect.Rf``
moves ZI-6150 (36.8 per m2K/W) as well as its own QI-6150, so the held ``dBPR``'s
effect on QI-6150, absorbed by the fouling, moves ZI-6150 against its own direct
effect: the outlet valve's shift is 0.00066 at the interval's ends, not the
0.0024 of its own gain alone.

A held parameter without an interval adds nothing (the band takes it as exact
and says so in ``result.json``); so does one the twin cannot change after
initialisation, or every held parameter when the step tests fail (a warning
names why). With several pairs the gain matrix is measured all the same, for the
loops' interaction (part 5 of :mod:`.bands`, :func:`band_parts`); where some output
tag is not paired, the tracked parameters are stepped (one pair too) for their gains
on it, the model-error part's (:mod:`.misfit`). With one pair, every output paired
and no held interval no simulation runs.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import TrackingError
from .bands import Fixed

log = logging.getLogger(__name__)

#: Step-test settings of :func:`held_parts` (those of ``pair``'s defaults).
TOLERANCE = 1e-4
BASELINE_TOLERANCE = 1e-3
MAX_TIME = 86400.0
#: fraction of the measured samples left out at each end of a tag's range (``pair``'s)
RANGE_TRIM = 0.005
#: step of a tracked parameter for the loops' gain matrix, as a fraction of its bounds' range (``pair``'s)
STEP = 0.05
#: largest condition number of the scaled gain matrix the loops' joint shift is computed from
MAX_CONDITION = 1e8


def held_intervals(spec: Any) -> dict[str, tuple[float, float, float]]:
    """The parameters the twin holds at an estimate with an interval: name -> (value, lower, upper).

    ``[fixed]`` values with a ``[fixed_intervals]`` entry and the ``[[parameters]]`` no pair
    tracks that carry an ``interval``; an interval of zero width is left out (nothing to step).
    """
    tracked = {p.parameter for p in getattr(spec, "pairs", ())}
    out: dict[str, tuple[float, float, float]] = {}
    for name, (a, b) in dict(getattr(spec, "fixed_intervals", None) or {}).items():
        if name in spec.fixed:
            out[name] = (float(spec.fixed[name]), float(a), float(b))
    for p in getattr(spec, "parameters", ()):
        if p.name not in tracked and getattr(p, "interval", None) is not None:
            out[p.name] = (float(p.start), float(p.interval[0]), float(p.interval[1]))
    return {k: v for k, v in out.items() if v[2] > v[1]}


@dataclass(frozen=True)
class Responses:
    """What :func:`measure` read on the twin.

    Attributes
    ----------
    held
        Name -> (estimate, lower, upper) of every held parameter with an interval.
    dy
        Held parameter -> (tag -> settled change at its interval's lower end, the same at its upper end).
    refused
        Held parameters the twin cannot change after initialisation (taken as exact).
    tags, parameters
        The pairs' tags and parameters, pair by pair (the rows and columns of *gains*).
    gains
        ``G_tt``: steady change of tag ``i`` per unit of parameter ``j`` (None with one pair: not measured).
    others, other_gains
        The output tags no pair tracks and ``G_ut``, their steady change per unit of each tracked parameter
        (rows *others*, columns *parameters*; None where not measured): the model-error part's
        (:mod:`.misfit`).
    """

    held: dict[str, tuple[float, float, float]]
    dy: dict[str, tuple[dict[str, float], dict[str, float]]]
    refused: list[str]
    tags: tuple[str, ...]
    parameters: tuple[str, ...]
    gains: np.ndarray | None
    others: tuple[str, ...] = ()
    other_gains: np.ndarray | None = None


def held_parts(spec: Any) -> tuple[dict[str, list[Fixed]], str]:
    """Per tracked parameter, the :class:`~.bands.Fixed` shifts of its truth, and a note ('' if none).

    Empty when the twin holds nothing with an interval (no simulation either with one pair). The note says why held
    parameters with an interval were left out (taken as exact), or why the loops' interaction was not used.
    """
    fixed, note, _, _ = band_parts(spec)
    return fixed, note


def band_parts(spec: Any) -> tuple[dict[str, list[Fixed]], str, np.ndarray | None, dict[str, list[float]] | None]:
    """What :class:`~.bands.BandTracker` takes from the twin: the fixed part (:func:`held_parts`), a note, the
    loops' gain matrix ``G_tt`` (part 5 of :mod:`.bands`; None with one pair, or where it could not be measured
    or inverted: the note says why), and the untracked tags' closed-loop gains (its *misfit*,
    :func:`trackingbox.identify.misfit.closed_gains`; None where none were measured). No simulation without
    held parameters, several pairs or an untracked output tag."""
    found, note = measure(spec)
    if found is None:
        return {}, note, None, None
    fixed, note = shifts(spec, found)
    gains = loop_gains(spec, found)
    misfit = None
    if found.other_gains is not None and found.others:
        from .misfit import closed_gains

        if gains is not None or len(found.parameters) == 1:  # the loops' matrix, or one loop: none needed
            closed = closed_gains(gains, found.other_gains)
            misfit = {t: [float(v) for v in row] for t, row in zip(found.others, closed)}
    return fixed, note, gains, misfit


def loop_gains(spec: Any, found: Responses) -> np.ndarray | None:
    """*found*'s gain matrix ``G_tt`` where it can be inverted (None without one, or where it is singular)."""
    if found.gains is None or _singular(found.gains, _scales(spec, found)):
        return None
    return np.array(found.gains, dtype=float)


def measure(spec: Any, *, joint: bool | None = None, others: bool = True) -> tuple[Responses | None, str]:
    """The step tests of :func:`held_parts`: (responses, '') or (None, why none; '' when nothing is held).

    *joint*: also measure the tracked parameters' gain matrix (default: with more than one pair); *others*: and
    their gains on the output tags no pair tracks (the tracked parameters stepped even with one pair).
    """
    held = held_intervals(spec)
    pairs = list(getattr(spec, "pairs", None) or ())
    if joint is None:
        joint = len(pairs) > 1
    paired = {p.variable for p in pairs}
    untracked = tuple(t for t in getattr(spec, "outputs", {}) if t not in paired) if others else ()
    if not pairs or not (held or joint or untracked):
        return None, ""
    try:
        return _responses(spec, held, joint, untracked), ""
    except (TrackingError, ValueError, KeyError, OSError) as exc:  # e.g. the online mode's record, too short yet
        what = ", ".join([*sorted(held), *(["the tracked parameters"] if joint else [])])
        note = (f"the twin's response to {what} could not be measured ({exc}): "
                + ("taken as exact" if held else "each band from its own loop alone"))
        log.warning("bands: %s", note)
        return None, note


def shifts(spec: Any, found: Responses, *, joint: bool = True) -> tuple[dict[str, list[Fixed]], str]:
    """Per tracked parameter the :class:`~.bands.Fixed` shifts from *found*, and a note.

    With the gain matrix measured (and *joint*): the loops' joint steady shift (:func:`joint_shifts`);
    otherwise each pair's ``-Δy/gain`` with its own gain.
    """
    held, dy = found.held, found.dy
    notes = [f"{', '.join(found.refused)}: the twin cannot change it after initialisation, taken as exact"] \
        if found.refused else []
    out: dict[str, list[Fixed]] = {}
    matrix = found.gains if joint else None
    if matrix is not None:
        scale = _scales(spec, found)
        why = _singular(matrix, scale)
        if why:
            notes.append(f"the tracked parameters' gain matrix {why}: each pair's shift uses its own gain only")
            log.warning("bands: %s", notes[-1])
            matrix = None
    if matrix is not None:
        log.info("bands: the loops' steady gains (rows %s; columns %s): %s", ", ".join(found.tags),
                 ", ".join(found.parameters), np.array2string(matrix, precision=4))
        for name, (lo, hi) in dy.items():
            at = [joint_shifts(matrix, np.array([side[t] for t in found.tags])) for side in (lo, hi)]
            for j, par in enumerate(found.parameters):
                out.setdefault(par, []).append(Fixed(name, float(at[0][j]), float(at[1][j])))
    else:
        for pair in spec.pairs:
            gain = float(pair.gain)
            if not (math.isfinite(gain) and gain != 0.0):
                continue
            out[pair.parameter] = [Fixed(name, -lo[pair.variable] / gain, -hi[pair.variable] / gain)
                                   for name, (lo, hi) in dy.items()]
    for par, fixed in out.items():
        for f in fixed:
            log.info("bands: %s held at %g (interval %g..%g) puts the truth of %s %.4g..%+.4g from its tracked "
                     "value", f.name, held[f.name][0], held[f.name][1], held[f.name][2], par, f.at_lower, f.at_upper)
    return out, "; ".join(notes)


def joint_shifts(gains: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """The tracked parameters' steady shift ``-G⁻¹ Δy`` when the loops absorb a change *dy* of their tags.

    *gains*: ``G[i, j]``, tag ``i`` of pair ``i`` per unit of the parameter of pair ``j``. The loops drive every
    paired tag back to the measurement, so ``G Δθ + Δy = 0``. One pair: ``-Δy/gain``.

    >>> joint_shifts(np.array([[1.0, 0.5], [0.8, 1.0]]), np.array([0.6, 0.0]))
    array([-1. ,  0.8])
    """
    return -np.linalg.solve(np.asarray(gains, dtype=float), np.asarray(dy, dtype=float))


def _scales(spec: Any, found: Responses) -> tuple[np.ndarray, np.ndarray]:
    """(per tag, per parameter) scales of the gain matrix's condition test: the tags' step-test ranges are
    not kept, so the tags' largest response to a full-range step, and the parameters' bounds' ranges."""
    spans = np.array([float(spec.parameter(p).max - spec.parameter(p).min) for p in found.parameters])
    assert found.gains is not None
    rows = np.max(np.abs(found.gains) * spans[None, :], axis=1)
    return np.where(rows > 0, rows, 1.0), spans


def _singular(gains: np.ndarray, scale: tuple[np.ndarray, np.ndarray]) -> str:
    """Why *gains* cannot be inverted ('' when it can): not finite, or its scaled condition number too large."""
    if not np.all(np.isfinite(gains)):
        return "is not known everywhere (a step test gave no settled value)"
    scaled = gains / scale[0][:, None] * scale[1][None, :]
    cond = float(np.linalg.cond(scaled))
    if not (math.isfinite(cond) and cond <= MAX_CONDITION):
        return f"is singular (scaled condition number {cond:.3g})"
    return ""


def _responses(spec: Any, held: dict[str, tuple[float, float, float]], joint: bool,
               untracked: tuple[str, ...] = ()) -> Responses:
    """Settled change of each paired tag with each held parameter at its interval's (lower, upper) end, and
    with *joint* the tracked parameters' gain matrix on their tags (each stepped by ``±STEP`` of its range),
    with *untracked* (output tags no pair tracks) their gains on those too."""
    from dataclasses import replace

    from ..analysis.rga import variable_ranges
    from ..analysis.steptest import (RunPlan, StepSettings, baseline, default_ranges, make_problem,
                                     operating_point, run_against_reference)
    from ..data import MeasurementView
    from ..fmu.info import change_refusal, read_info

    info = read_info(spec.twin)
    refused = sorted(n for n in held if change_refusal(info, n) is not None)
    names = [n for n in held if n not in refused]
    tags = list(dict.fromkeys(p.variable for p in spec.pairs))
    tracked = [p.parameter for p in spec.pairs]
    if len(tags) != len(tracked) or len(set(tracked)) != len(tracked):
        joint, untracked = False, ()  # two pairs on one tag or one parameter: no square matrix (the pairs' own gains)
    step_tracked = joint or bool(untracked)
    if not names and not step_tracked:
        return Responses(held, {}, refused, tuple(tags), tuple(tracked), None)
    every = tags + [t for t in untracked if t in spec.outputs]
    view = MeasurementView.from_spec(spec, "training" if "training" in spec.windows else "all")
    frame, scored = view.to_frame(), view.to_frame(scored=True)
    train = scored[view.in_window]
    spans = variable_ranges(train[every].to_numpy(dtype=float), trim=RANGE_TRIM) if len(train) else \
        np.full(len(every), np.nan)
    op = operating_point(frame, spec.inputs, start=float(view.window[0]), duration=3600.0)
    values = {**{p.name: float(p.start) for p in spec.parameters}, **{k: float(v) for k, v in spec.fixed.items()}}
    freeze = dict(spec.pairing.freeze)
    steps: list[tuple[str, float]] = []
    if step_tracked:
        for name in tracked:
            q = spec.parameter(name)
            d = STEP * (q.max - q.min)
            steps += [(name, v) for v in dict.fromkeys(min(q.max, max(q.min, q.start + s * d)) for s in (1, -1))
                      if v != q.start]
    stepped = list(dict.fromkeys(n for n, _ in steps))
    problem = make_problem(spec.twin, outputs={t: spec.outputs[t] for t in every},
                           parameters=[(n, held[n][0], held[n][1], held[n][2]) for n in names]
                           + [(n, values[n], spec.parameter(n).min, spec.parameter(n).max) for n in stepped],
                           fixed={k: v for k, v in values.items() if k not in names and k not in stepped},
                           operating=op,
                           ranges={t: float(r) for t, r in zip(every, spans) if math.isfinite(r) and r > 0},
                           freeze=freeze,
                           compensation=[(st.variable, st.correction, st.gain) for st in spec.states])
    interval = float(spec.sample_time)
    settings = StepSettings(freeze=tuple(freeze.items()), interval=interval, window=60.0 * interval,
                            tolerance=TOLERANCE, baseline_tolerance=BASELINE_TOLERANCE, max_time=MAX_TIME,
                            steady_start=spec.data.initial == "steady")
    if not all(math.isfinite(r) and r > 0 for r in problem.ranges):
        problem = replace(problem, ranges=default_ranges(problem, settings))
    log.info("bands: step tests of the held %s to their intervals' ends%s", ", ".join(names),
             f" and of the tracked {', '.join(tracked)}" if steps else "")
    base = baseline(problem, settings)
    moves = [((n, held[n][1 + side]), f"{n} at the {'upper' if side else 'lower'} end of its interval")
             for n in names for side in (0, 1)] + [((n, v), f"{n} stepped to {v:g}") for n, v in steps]
    plans = [RunPlan(problem.fmu, problem.start_values(), problem.outputs, problem.ranges, settings,
                     base.freeze_time, base.step_time, (move,), label=label, states=base.states,
                     compensation=problem.compensation, levels_ref=base.levels_ref)
             for move, label in moves]
    _, results, _ = run_against_reference(problem, settings, base, plans)
    change = [r.after - r.before for r in results]
    out: dict[str, tuple[dict[str, float], dict[str, float]]] = {}
    for i, n in enumerate(names):
        lo, hi = change[2 * i], change[2 * i + 1]
        out[n] = ({t: float(lo[j]) for j, t in enumerate(tags)}, {t: float(hi[j]) for j, t in enumerate(tags)})
    every_gains = None
    if step_tracked:
        every_gains = np.full((len(every), len(tracked)), math.nan)
        k = 2 * len(names)
        for j, name in enumerate(tracked):
            at = [(v, change[k + i]) for i, (n, v) in enumerate(steps) if n == name]
            start = spec.parameter(name).start
            if len(at) == 2:  # the secant through both steps
                every_gains[:, j] = (at[0][1] - at[1][1]) / (at[0][0] - at[1][0])
            elif len(at) == 1:  # a start at a bound: the step against the unstepped run
                every_gains[:, j] = at[0][1] / (at[0][0] - start)
    gains = every_gains[:len(tags)] if every_gains is not None and joint else None
    rest = tuple(every[len(tags):])
    return Responses(held, out, refused, tuple(tags), tuple(tracked), gains, rest,
                     every_gains[len(tags):] if every_gains is not None and rest else None)
