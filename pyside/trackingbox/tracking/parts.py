"""The parts of the tracking loop that are not twins: the parameter controllers, the state
compensation, the output stream; the carried integrator's limits and the sub-steps rule.
"""
from __future__ import annotations

import csv
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from ..data import MeasurementView
from .controllers import ScaledPI
from .plan import PlannedPair, PlannedState
from .result import Fit, Stats, from_json_float

if TYPE_CHECKING:
    from .loop import TrackingLoop

log = logging.getLogger(__name__)



# --------------------------------------------------------------------------- the parts of the loop

class Controllers:
    """The parameter controllers of the ``[[pairs]]`` and their missing-data bookkeeping."""

    def __init__(self, pairs: Sequence[PlannedPair], ts: float) -> None:
        self.pairs = list(pairs)
        self.names = [p.parameter for p in self.pairs]
        #: the PI pairs (the box's law, which also moves within a sample)
        self._pi = [p for p in self.pairs if isinstance(p.controller, ScaledPI)]
        self.ts = float(ts)
        #: tag -> time its measurement went missing (None while present)
        self.missing: dict[str, float | None] = {p.tag: None for p in self.pairs}
        #: time of the last update (a sample or a sub-step); None before the first
        self.last_time: float | None = None

    def _dt(self, t: float) -> float | None:
        """Time since the last update, or None when it is the sample time (or there was none)."""
        if self.last_time is None:
            return None
        dt = t - self.last_time
        return None if math.isclose(dt, self.ts, rel_tol=1e-12) else dt

    def _advance(self, p: PlannedPair, sp: float, pv: float, hold: bool, dt: float | None) -> None:
        if dt is not None and isinstance(p.controller, ScaledPI):
            p.controller.update(sp, pv, hold=hold, dt=dt)
        else:
            p.controller.update(sp, pv, hold=hold)

    def substep(self, t: float, w: float, k: int, y: npt.NDArray[np.float64], ridx: Mapping[str, int],
                view: MeasurementView, hold: bool) -> None:
        """Advance the controllers to *t* inside the sample ``[t_k, t_k+1]``, a fraction *w* of it.

        The setpoint is the measurement interpolated linearly between the two
        samples, as the compiled box sees it (NaN when either is missing).
        Only the PI controllers (the box's law) move within a sample; a
        sliding-mode controller steps once a sample.
        """
        dt = self._dt(t)
        samples = view.samples
        for p in self._pi:
            s = samples[p.tag]
            sp = (1.0 - w) * float(s[k]) + w * float(s[k + 1])
            p.controller.update(sp, float(y[ridx[p.fmu_name]]), hold=hold, dt=dt)
        self.last_time = t

    def values(self) -> dict[str, float]:
        """Parameter name -> the value its controller outputs."""
        return {p.parameter: p.controller.value for p in self.pairs}

    def update(self, t: float, k: int, y: npt.NDArray[np.float64], ridx: Mapping[str, int], view: MeasurementView,
               hold: bool, event: Callable[..., None]) -> list[str]:
        """Advance every controller one sample (setpoint: the measured tag); return their modes."""
        modes = []
        dt = self._dt(t)
        for p in self.pairs:
            sp = float(view.samples[p.tag][k])
            pv = float(y[ridx[p.fmu_name]])
            ok = math.isfinite(sp)
            if not ok and self.missing[p.tag] is None:
                self.missing[p.tag] = t
                event(t, "missing", f"tag {p.tag!r} missing from t = {t:g} s: controller of "
                      f"{p.parameter!r} on hold", logging.INFO)
            elif ok and self.missing[p.tag] is not None:
                event(t, "resumed", f"tag {p.tag!r} back at t = {t:g} s after {t - self.missing[p.tag]:g} s; "
                      f"controller of {p.parameter!r} resumes (bumpless)", logging.INFO)
                self.missing[p.tag] = None
            self._advance(p, sp, pv, hold, dt)
            modes.append(p.controller.mode)
        self.last_time = t
        return modes

    def state_dict(self) -> dict[str, Any]:
        return {"controllers": {p.parameter: p.controller.state_dict() for p in self.pairs},
                "missing": dict(self.missing), "last_time": self.last_time}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        for p in self.pairs:
            p.controller.load_state_dict(state["controllers"][p.parameter])
        self.missing = {k: from_json_float(v) for k, v in state["missing"].items()}
        self.last_time = from_json_float(state["last_time"])


class Compensation:
    """State compensation of the ``[[states]]``: one compensator for each twin (tracked, untracked)."""

    def __init__(self, states: Sequence[PlannedState]) -> None:
        self.states = list(states)
        self.names = [s.correction for s in self.states]

    def update(self, k: int, y: npt.NDArray[np.float64], yu: npt.NDArray[np.float64] | None,
               ridx: Mapping[str, int], view: MeasurementView) -> tuple[dict[str, float], dict[str, float]]:
        """Correction flows for the tracked twin and the untracked one (NaN without it)."""
        corr, corr_u = {}, {}
        for s in self.states:
            meas = float(view.samples[s.tag][k])
            corr[s.correction] = s.tracked.update(meas, float(y[ridx[s.variable]]))
            corr_u[s.correction] = s.untracked.update(meas, float(yu[ridx[s.variable]])) \
                if yu is not None else math.nan
        return corr, corr_u

    def state_dict(self) -> dict[str, Any]:
        return {"tracked": {s.correction: s.tracked.state_dict() for s in self.states},
                "untracked": {s.correction: s.untracked.state_dict() for s in self.states}}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        for s in self.states:
            s.tracked.load_state_dict(state["tracked"][s.correction])
            s.untracked.load_state_dict(state["untracked"][s.correction])


class Output:
    """The streamed CSV and the summaries of the run (parameter, correction and level ranges, fits)."""

    def __init__(self, path: Path, columns: Sequence[str], parameters: Sequence[str], corrections: Sequence[str],
                 levels: Sequence[str], fitted: Sequence[str], bands: Any = None) -> None:
        self.path = path
        #: the tracked parameters' uncertainty bands (trackingbox.identify.bands.BandTracker): two more
        #: columns per pair after the row's own, computed from the row
        self.bands = bands
        self.columns = list(columns) + (list(bands.columns) if bands is not None else [])
        self.pstats = {n: Stats() for n in parameters}
        self.cstats = {n: Stats() for n in corrections}
        self.sstats = {n: Stats() for n in levels}
        self.fits = {t: Fit() for t in fitted}
        self._fh: Any = None
        self._writer: Any = None

    def open(self) -> None:
        """Start a new CSV with its header."""
        self._fh = open(self.path, "w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._fh)
        self._writer.writerow(self.columns)

    def write(self, row: Sequence[Any]) -> None:
        self._writer.writerow(row if self.bands is None else [*row, *self.bands.row(row)])

    def writerows(self, rows: Sequence[Sequence[Any]]) -> None:
        self._writer.writerows(rows if self.bands is None else [[*r, *self.bands.row(r)] for r in rows])

    def write_text(self, text: str, rows: Any = None) -> None:
        """Rows already formatted as the csv writer writes them (:func:`trackingbox.native.format_rows`);
        *rows*: the same rows as numbers (modes as flags), for the band columns."""
        if self.bands is not None:
            text = self.bands.append_text(text, rows)
        self._fh.write(text)

    def flush(self) -> None:
        if self._fh is not None:
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def state_dict(self) -> dict[str, Any]:
        """The CSV's valid length (bytes) and the summaries; flushes the CSV first."""
        self._fh.flush()
        return {"csv_bytes": self._fh.tell(),
                "bands": self.bands.state_dict() if self.bands is not None else None,
                "parameter_stats": {n: s.state() for n, s in self.pstats.items()},
                "correction_stats": {n: s.state() for n, s in self.cstats.items()},
                "state_stats": {n: s.state() for n, s in self.sstats.items()},
                "fits": {t: f.state() for t, f in self.fits.items()}}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Cut the CSV back to the saved length (rows after it are redone) and append from there."""
        with open(self.path, "r+b") as fh:
            fh.truncate(int(state["csv_bytes"]))
        for n in self.pstats:
            self.pstats[n].restore(state["parameter_stats"][n])
        for n in self.cstats:
            self.cstats[n].restore(state["correction_stats"][n])
        for n in self.sstats:
            self.sstats[n].restore(state["state_stats"][n])
        for t in self.fits:
            self.fits[t].restore(state["fits"][t])
        if self.bands is not None:
            self.bands.load_state_dict(state["bands"])
        self._fh = open(self.path, "a", newline="", encoding="utf-8")
        self._writer = csv.writer(self._fh)


# --------------------------------------------------------------------------- carrying the integrator

#: Largest change of a tracked parameter, as a fraction of its bound range, that the tracked twin's
#: integrator carries without a restart (corrections: of the compensator's gain times its level's range)
CARRY_FRACTION = 0.02


def carry_limits(fraction: float, pairs: Sequence[PlannedPair], states: Sequence[Any],
                  ranges: Mapping[str, tuple[int, float, float]]) -> dict[str, float]:
    """Value name -> the largest change the tracked twin's integrator carries (see :func:`track`).

    A parameter: *fraction* of its bound range. A correction flow: *fraction*
    of its compensator's gain times the measured range of its level (1st to
    99th percentile), the correction a level error of that size asks for.
    """
    limits = {p.parameter: fraction * (p.bounds[1] - p.bounds[0]) for p in pairs}
    for s in states:
        n, lo, hi = ranges[s.tag]  # percentile_range of the level's samples
        if n >= 2:
            limits[s.correction] = fraction * abs(float(s.gain)) * float(hi - lo)
    return limits


# --------------------------------------------------------------------------- sub-steps

#: Largest within-sample loop gain the automatic choice leaves to one step per sample ...
SUBSTEP_GAIN = 0.01
#: ... and the most sub-steps it chooses.
MAX_SUBSTEPS = 8


def within_sample_gains(loop: TrackingLoop) -> dict[str, float]:
    """Per PI pair: ``kp`` times the fraction of its steady-state response the twin shows one sample after a step.

    The compiled box's controller sees the twin answer its own parameter
    moves continuously; a runtime that reads the twin once a sample sees that
    answer a sample late. How much that matters is the loop gain closed within
    a sample: the proportional gain times the part of the pair's steady-state
    gain the variable reaches within one sample time. It is measured on the
    twin from the first sample (before the run starts): one sample with the
    start values, and one per pair with its parameter moved by a tenth of its
    range towards the middle, all else equal.
    """
    assert loop.twin is not None
    pairs = [p for p in loop.controllers.pairs if isinstance(p.controller, ScaledPI)]
    if not pairs or loop.n_rows < 2:
        return {}
    tw = loop.twin
    t1 = float(loop.grid[1])
    values = {**loop.controllers.values(), **{c: 0.0 for c in loop.compensation.names}}
    names = [p.fmu_name for p in pairs]

    def answer(changed: Mapping[str, float]) -> npt.NDArray[np.float64]:
        run = tw.model.stepper(start_time=0.0, parameters={**tw.base, **values, **changed}, inputs=tw.inputs,
                               max_step=tw.max_step, input_rule=tw.input_rule)
        if tw.steady_start:
            run.settle()
        run.step(t1)
        y = np.asarray(run.get(names), dtype=float)
        run.finish()
        return y

    y0 = answer({})
    gains = {}
    for j, p in enumerate(pairs):
        ctrl = p.controller
        lo, hi = p.bounds
        delta = 0.1 * (hi - lo) * (1.0 if ctrl.u < 50.0 else -1.0)
        dy = float(answer({p.parameter: ctrl.value + delta})[j] - y0[j])
        fraction = abs(dy) / (ctrl.scaling.span * abs(delta) / (hi - lo))
        gains[p.parameter] = ctrl.kp * fraction if math.isfinite(fraction) else 0.0
        log.info("pair %s -> %s: %.3g of the steady-state answer within one sample; within-sample loop gain %.3g",
                 p.tag, p.parameter, fraction, gains[p.parameter])
    return gains


def substeps_for(gains: Mapping[str, float]) -> int:
    """Sub-steps per sample for within-sample loop gains (:func:`within_sample_gains`)."""
    g = max(gains.values(), default=0.0)
    if g <= SUBSTEP_GAIN:
        return 1
    return min(MAX_SUBSTEPS, math.ceil(math.sqrt(g / SUBSTEP_GAIN)))
