"""The set-up of a tracking run: the pairs, the compensated states, the controllers and the
data of one window (:func:`make_plan`), read from the spec and its measurement view.
"""
from __future__ import annotations

import csv
import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..data import MeasurementView
from ..errors import DataError, SpecError, unknown_name
from ..stream import WindowedMeasurements
from .controllers import Interpolation, ScaledPI, SlidingMode, StateCompensator
from .result import TrackingEvent
from .tuning import pair_settings

if TYPE_CHECKING:
    from ..spec import Spec

log = logging.getLogger(__name__)



Window = Literal["training", "validation", "all"]
#: How the parameter controllers and compensators are integrated with the twin (see :func:`track`)
ControllerMode = Literal["discrete", "continuous"]

#: Sliding-mode boundary layer (% of the variable span) when a pair asks for it.
SLIDING_PHI = 5.0


# --------------------------------------------------------------------------- set-up

@dataclass
class PlannedPair:
    tag: str
    fmu_name: str
    parameter: str
    controller: ScaledPI | SlidingMode
    bounds: tuple[float, float]


@dataclass
class PlannedState:
    tag: str
    variable: str
    correction: str
    tracked: StateCompensator
    untracked: StateCompensator


@dataclass
class Plan:
    view: MeasurementView                  # grid, samples, stoppage mask, twin inputs, scored samples
    columns: list[str]
    read_names: list[str]                  # twin variables read each step (output + state variables)
    out_tags: list[str]                    # tags with a tracked/untracked column, in column order
    tag_var: dict[str, str]
    untracked_table: dict[str, npt.NDArray[np.float64]] | None = None
    events: list[TrackingEvent] = field(default_factory=list)


def make_controller(spec: Any, pair: Any, measured: npt.NDArray[np.float64],
                     interpolation: Interpolation = "linear") -> PlannedPair:
    p = spec.parameter(pair.parameter)
    ts = float(spec.sample_time)
    # the one span/tuning rule, shared with the generated Modelica box
    settings = pair_settings(pair, float(p.min), float(p.max), ts=ts, where=spec.path.name)
    scaling, kp, ti, direction = settings.scaling, settings.kp, settings.ti, settings.direction
    span = scaling.span
    kind = getattr(pair, "controller", "pi")
    if kind == "sliding":
        ctrl: ScaledPI | SlidingMode = SlidingMode.from_pi(scaling, kp=kp, ti=ti, ts=ts, direction=direction,
                                                           p0=p.start, phi=SLIDING_PHI)
    else:
        ctrl = ScaledPI(scaling, kp=kp, ti=ti, ts=ts, direction=direction, p0=p.start, interpolation=interpolation)
    log.info("pair %s -> %s: %s kp=%.4g ti=%.4g s (scaled), span=%.4g, %s acting", pair.variable, pair.parameter,
             kind, kp, ti, span, "direct" if direction > 0 else "reverse")
    return PlannedPair(pair.variable, spec.outputs[pair.variable], pair.parameter, ctrl, (p.min, p.max))


def check_authority(pair: PlannedPair, measured: tuple[int, float, float], events: list[TrackingEvent]) -> None:
    """Warn when the parameter's whole range moves the variable by little compared with the data.

    ``|gain|·(p_max - p_min)`` (the controller's span) below 5 % of the measured
    range (1st-99th percentile) means the controller can only correct a small
    part of the error and will sit at a bound: a pairing problem, not a tuning one.
    """
    n, lo, hi = measured  # percentile_range of the variable's samples
    if n < 10:
        return
    rng = float(hi - lo)
    span = pair.controller.scaling.span
    if rng > 0.0 and span < 0.05 * rng:
        msg = (f"pair {pair.tag!r} -> {pair.parameter!r}: the parameter's whole range "
               f"[{pair.bounds[0]:g}, {pair.bounds[1]:g}] moves {pair.tag!r} by only {span:.3g} "
               f"against a measured range of {rng:.3g}; the controller will mostly sit at a bound "
               "(consider another pairing)")
        log.warning(msg)
        events.append(TrackingEvent(0.0, "weak-pair", msg))


def make_plan(spec: Spec, window: Window, untracked: bool | pd.DataFrame, view: MeasurementView | None = None,
          stream: WindowedMeasurements | None = None) -> Plan:
    if not spec.pairs:
        raise SpecError(f"spec {spec.path} has no [[pairs]]; run `trackingbox pair` first or add them")
    problems = []
    for pair in spec.pairs:
        if pair.variable not in spec.outputs:
            problems.append(unknown_name("tracking variable", pair.variable, spec.outputs, f"[outputs] of {spec.path}"))
    if problems:
        raise DataError("; ".join(problems))
    if view is None:
        view = MeasurementView.from_spec(spec, window, skip=float(spec.tracking.hold_until))
    elif view.grid.size == 0 or view.grid[0] != 0.0 or view.skip != float(spec.tracking.hold_until):
        raise DataError(f"the measurement view given to track() must start at the first sample and skip the "
                        f"start-up hold ({spec.tracking.hold_until:g} s): build it with "
                        f"MeasurementView.from_spec(spec, {window!r}, skip=spec.tracking.hold_until)")
    where = view.source.name
    grid = view.grid
    for tag in spec.inputs:
        if stream is not None:
            missing, size, last = stream.input_missing[tag], stream.n_rows, stream.grid[-1]
        else:
            bad = ~np.isfinite(view.values(tag))
            missing, size, last = int(bad.sum()), bad.size, grid[-1]
        if missing == size:
            raise DataError(f"input tag {tag!r} in {where} has no valid value between 0 and {last:g} s")
        if missing:
            log.warning("input tag %r in %s is missing at %d of %d samples; interpolated/held for the twin",
                        tag, where, missing, size)

    out_tags: list[str] = list(spec.outputs)
    tag_var = dict(spec.outputs)
    for s in spec.states:
        if s.tag not in tag_var:
            out_tags.append(s.tag)
            tag_var[s.tag] = s.variable
    read_names = list(dict.fromkeys(tag_var[t] for t in out_tags))
    cols = ["time"]
    for tag in out_tags:
        cols += [f"measured:{tag}", f"tracked:{tag}", f"untracked:{tag}"]
    cols += [f"parameter:{p.parameter}" for p in spec.pairs]
    cols += [f"correction:{s.correction}" for s in spec.states]
    cols += [f"untracked_correction:{s.correction}" for s in spec.states]
    cols += [f"mode:{p.variable}" for p in spec.pairs]
    untracked_table = None
    if isinstance(untracked, pd.DataFrame):
        if "time" not in untracked.columns:
            raise DataError("the untracked simulation table has no 'time' column")
        ut = untracked["time"].to_numpy(dtype=float)
        untracked_table = {}
        for name in read_names:
            if name not in untracked.columns:
                raise DataError(unknown_name("column", name, untracked.columns, "the untracked simulation table"))
            untracked_table[name] = np.interp(grid, ut, untracked[name].to_numpy(dtype=float))
    return Plan(view, cols, read_names, out_tags, tag_var, untracked_table)


def read_rows(path: Path, upto: int, columns: Mapping[str, str], grid: npt.NDArray[np.float64],
               ) -> Iterator[tuple[float, dict[str, float]]]:
    """Recorded values (name -> its CSV column) of rows ``0 .. upto-1``, as replay steps ``(t_next, values)``."""
    if upto <= 0:
        return
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        idx = {name: header.index(column) for name, column in columns.items()}
        for k, row in enumerate(reader):
            if k >= upto:
                break
            yield float(grid[k + 1]), {n: float(row[j]) for n, j in idx.items()}
