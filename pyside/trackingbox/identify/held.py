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
quadrature. The loops' interaction is not modelled (each pair's own gain only),
as the controllers themselves are tuned.

A held parameter without an interval adds nothing (the band takes it as exact
and says so in ``result.json``); so does one the twin cannot change after
initialisation, or every held parameter when the step tests fail (a warning
names why). Without any held interval no simulation runs and the band is what
it was before.
"""
from __future__ import annotations

import logging
import math
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


def held_parts(spec: Any) -> tuple[dict[str, list[Fixed]], str]:
    """Per tracked parameter, the :class:`~.bands.Fixed` shifts of its truth, and a note ('' if none).

    Empty (and no simulation) when the twin holds nothing with an interval. The note says why held
    parameters with an interval were left out (taken as exact).
    """
    held = held_intervals(spec)
    if not held or not getattr(spec, "pairs", None):
        return {}, ""
    try:
        dy, refused = _responses(spec, held)
    except (TrackingError, ValueError, KeyError, OSError) as exc:  # e.g. the online mode's record, too short yet
        note = f"the twin's response to {', '.join(sorted(held))} could not be measured ({exc}): taken as exact"
        log.warning("bands: %s", note)
        return {}, note
    out: dict[str, list[Fixed]] = {}
    for pair in spec.pairs:
        gain = float(pair.gain)
        if not (math.isfinite(gain) and gain != 0.0):
            continue
        out[pair.parameter] = [Fixed(name, -lo[pair.variable] / gain, -hi[pair.variable] / gain)
                               for name, (lo, hi) in dy.items()]
    for pair in spec.pairs:
        for f in out.get(pair.parameter, ()):
            log.info("bands: %s held at %g (interval %g..%g) puts the truth of %s %.4g..%+.4g from its tracked "
                     "value", f.name, held[f.name][0], held[f.name][1], held[f.name][2], pair.parameter,
                     f.at_lower, f.at_upper)
    note = (f"{', '.join(refused)}: the twin cannot change it after initialisation, taken as exact"
            if refused else "")
    return out, note


def _responses(spec: Any, held: dict[str, tuple[float, float, float]]
               ) -> tuple[dict[str, tuple[dict[str, float], dict[str, float]]], list[str]]:
    """Settled change of each paired tag with each held parameter at its interval's (lower, upper) end."""
    from dataclasses import replace

    from ..analysis.rga import variable_ranges
    from ..analysis.steptest import (RunPlan, StepSettings, baseline, default_ranges, make_problem,
                                     operating_point, run_against_reference)
    from ..data import MeasurementView
    from ..fmu.info import change_refusal, read_info

    info = read_info(spec.twin)
    refused = sorted(n for n in held if change_refusal(info, n) is not None)
    names = [n for n in held if n not in refused]
    if not names:
        return {}, refused
    view = MeasurementView.from_spec(spec, "training" if "training" in spec.windows else "all")
    frame, scored = view.to_frame(), view.to_frame(scored=True)
    tags = list(dict.fromkeys(p.variable for p in spec.pairs))
    train = scored[view.in_window]
    spans = variable_ranges(train[tags].to_numpy(dtype=float), trim=RANGE_TRIM) if len(train) else \
        np.full(len(tags), np.nan)
    op = operating_point(frame, spec.inputs, start=float(view.window[0]), duration=3600.0)
    values = {**{p.name: float(p.start) for p in spec.parameters}, **{k: float(v) for k, v in spec.fixed.items()}}
    freeze = dict(spec.pairing.freeze)
    problem = make_problem(spec.twin, outputs={t: spec.outputs[t] for t in tags},
                           parameters=[(n, held[n][0], held[n][1], held[n][2]) for n in names],
                           fixed={k: v for k, v in values.items() if k not in names}, operating=op,
                           ranges={t: float(r) for t, r in zip(tags, spans) if math.isfinite(r) and r > 0},
                           freeze=freeze,
                           compensation=[(st.variable, st.correction, st.gain) for st in spec.states])
    interval = float(spec.sample_time)
    settings = StepSettings(freeze=tuple(freeze.items()), interval=interval, window=60.0 * interval,
                            tolerance=TOLERANCE, baseline_tolerance=BASELINE_TOLERANCE, max_time=MAX_TIME,
                            steady_start=spec.data.initial == "steady")
    if not all(math.isfinite(r) and r > 0 for r in problem.ranges):
        problem = replace(problem, ranges=default_ranges(problem, settings))
    log.info("bands: step tests of the held %s to their intervals' ends", ", ".join(names))
    base = baseline(problem, settings)
    plans = [RunPlan(problem.fmu, problem.start_values(), problem.outputs, problem.ranges, settings,
                     base.freeze_time, base.step_time, ((n, held[n][1 + side]),),
                     label=f"{n} at the {'upper' if side else 'lower'} end of its interval", states=base.states,
                     compensation=problem.compensation, levels_ref=base.levels_ref)
             for n in names for side in (0, 1)]
    _, results, _ = run_against_reference(problem, settings, base, plans)
    out: dict[str, tuple[dict[str, float], dict[str, float]]] = {}
    for i, n in enumerate(names):
        lo, hi = (results[2 * i + side].after - results[2 * i + side].before for side in (0, 1))
        out[n] = ({t: float(lo[j]) for j, t in enumerate(tags)}, {t: float(hi[j]) for j, t in enumerate(tags)})
    return out, refused
