"""The tracking loop: :class:`TrackingLoop`, step the twins beside the plant data row by row.

See :mod:`trackingbox.tracking.runtime` for what a run does; this module holds the loop
itself (its parts are in :mod:`.parts`, :mod:`.twin`, :mod:`.rows`, its set-up in
:mod:`.plan`, what it returns in :mod:`.result`).
"""
from __future__ import annotations

import json
import logging
import math
import time as _time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import pandas as pd

from .. import config
from ..checkpoint import CheckpointFile
from ..data import MeasurementView
from ..errors import DataError, SimulationError, SpecError
from ..generate.inputs_twin import inputs_twin as make_inputs_twin
from ..identify.hooks import band_tracker
from ..io import write_text_atomic
from ..spec import check_against_fmu
from ..stream import MARGIN_ROWS, WINDOW_ROWS, WindowedMeasurements, percentile_range
from .controllers import Interpolation, ScaledPI, StateCompensator
from .parts import (
    CARRY_FRACTION,
    Compensation,
    Controllers,
    Output,
    carry_limits,
    substeps_for,
    within_sample_gains,
)
from .plan import (
    ControllerMode,
    PlannedState,
    Window,
    check_authority,
    make_controller,
    make_plan,
)
from .result import (
    CHECKPOINT_NAME,
    CSV_NAME,
    RESULT_NAME,
    ParameterResult,
    TrackingEvent,
    TrackingResult,
    jsonify,
    num,
    unjsonify,
)
from .rows import NATIVE_ROWS_ENV, ClosedRows, NativeRows
from .twin import Twin

if TYPE_CHECKING:
    from ..spec import Spec

log = logging.getLogger(__name__)



CHECKPOINT_VERSION = 9  # 9: the bands' day-long rate; 8: the bands' slow part (batch means); 7: band columns; 6: controller mode; 5: carried integrator (carry, hold flag); 4: sub-steps; 3: error interpolation in the controllers; 2: one entry per part


# --------------------------------------------------------------------------- the loop

class TrackingLoop:
    """The tracking loop over a spec's measurement view, made of parts that save their own state.

    Parts: the parameter controllers, the state compensation, the tracked twin,
    the untracked twin (optional) and the output stream (CSV and summaries).
    Each has ``state_dict()`` / ``load_state_dict()``; :meth:`state_dict` of
    the loop is theirs plus the loop's own (row, recovery hold, events) and is
    what ``checkpoint.json`` holds. Use it through :func:`track`, or::

        loop = TrackingLoop(spec, out_dir=out)
        try:
            loop.begin(resume=False)
            loop.run()
        finally:
            loop.close()
        result = loop.result()

    Parameters are those of :func:`track`.
    """

    def __init__(self, spec: Spec, *, out_dir: str | Path, window: Window = "all",
                 untracked: bool | pd.DataFrame = True, checkpoint_every: int = 200,
                 recovery_hold: float | None = None, tolerance: float = 1e-6,
                 view: MeasurementView | None = None, interpolation: Interpolation = "linear",
                 substeps: int | Literal["auto"] = "auto", carry: float = CARRY_FRACTION,
                 controllers: ControllerMode = "discrete", inputs_twin: Any = None,
                 window_rows: int | None = None, stream: Any = None) -> None:
        self.wall0 = _time.perf_counter()
        self.spec = spec
        self.window = window
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.csv_path = self.out_dir / CSV_NAME
        self.ckpt_path = self.out_dir / CHECKPOINT_NAME
        self.checkpoint_every = int(checkpoint_every)
        self._ckpt = CheckpointFile(self.ckpt_path, self.csv_path)
        check_against_fmu(spec)
        #: the run's measurements window by window (:mod:`trackingbox.stream`); None: the whole view
        #: (given, or where windows are not exact), with :attr:`view` that view
        self.stream: WindowedMeasurements | None = None
        rows = WINDOW_ROWS if window_rows is None else int(window_rows)
        if rows > 0 and controllers == "continuous":  # a window holds a whole batch (see _window_for)
            rows = max(rows, NativeRows.CAP + MARGIN_ROWS + 2)
        stat_tags = list(dict.fromkeys([*(p.variable for p in spec.pairs if p.variable in spec.outputs),
                                        *(s.tag for s in spec.states)]))
        if stream is not None:  # given: a growing stream of the online mode (trackingbox.online.livestream)
            self.stream = stream
            view = stream.view(0, min(stream.n_rows, stream.rows_per_window + MARGIN_ROWS))
        elif view is None and rows > 0 and spec.pairs and not isinstance(untracked, pd.DataFrame):
            self.stream = WindowedMeasurements.open(spec, window, skip=float(spec.tracking.hold_until),
                                                    directory=self.out_dir, stats_tags=stat_tags,
                                                    rows_per_window=rows)
            if self.stream is not None:
                if all(self.stream.input_missing[t] < self.stream.n_rows for t in spec.inputs):
                    view = self.stream.view(0, min(self.stream.n_rows, rows + MARGIN_ROWS))
                else:  # an input with no value: the whole view's checks word it
                    self.stream.close()
                    self.stream = None
        try:
            self.plan = plan = make_plan(spec, window, untracked, view, self.stream)
        except BaseException:
            if self.stream is not None:
                self.stream.close()
            raise
        #: the current window (the whole view without :attr:`stream`) and the row of the run its first row is
        self.view = plan.view
        self.off = 0
        self.grid: Any = self.stream.grid if self.stream is not None else plan.view.grid
        self.n_rows = int(self.grid.size)
        #: tag -> (valid samples, 1st, 99th percentile) over the run, of each pair's variable and each level
        self.ranges = {tag: self.stream.percentiles(tag) if self.stream is not None
                       else percentile_range(self.view.samples[tag]) for tag in stat_tags}
        #: the twins' steppers run (their input tables follow the windows)
        self._running = False
        self.ts = ts = float(spec.sample_time)
        self.hold_until = float(spec.tracking.hold_until)
        self.recovery_hold = 10.0 * ts if recovery_hold is None else float(recovery_hold)
        self.events = plan.events

        if interpolation not in ("zoh", "linear"):
            raise ValueError(f"interpolation must be 'zoh' or 'linear', got {interpolation!r}")
        if controllers not in ("discrete", "continuous"):
            raise ValueError(f"controllers must be 'discrete' or 'continuous', got {controllers!r}")
        self.mode: ControllerMode = controllers
        continuous = controllers == "continuous"
        if continuous:
            if interpolation != "linear":
                raise ValueError("controllers='continuous' integrates the box's law on the interpolated "
                                 f"measurement: it needs interpolation='linear', not {interpolation!r}")
            if substeps not in ("auto", 1):
                raise ValueError(f"controllers='continuous' integrates the controllers with the twin: there are "
                                 f"no sub-steps to choose (got substeps={substeps!r})")
            if any(getattr(p, "controller", "pi") != "pi" for p in spec.pairs):
                raise SpecError(f"controllers='continuous' runs PI pairs only; {spec.path} has a sliding-mode pair")
            if spec.data.inputs != "linear":
                raise SpecError(f"controllers='continuous' integrates the controllers with the twin on its inputs "
                                f"interpolated in C: it needs [data] inputs = \"linear\", not "
                                f"{spec.data.inputs!r} ({spec.path})")
            if inputs_twin is None:
                inputs_twin = make_inputs_twin(spec)
        #: the twin with its tracked parameters as inputs (continuous mode), else None
        self.inputs_twin = inputs_twin
        self.interpolation = interpolation
        pairs = [make_controller(spec, p, self.view.samples[p.variable], interpolation) for p in spec.pairs]
        for p in pairs:
            check_authority(p, self.ranges[p.tag], self.events)
        self.controllers = Controllers(pairs, ts)
        self.compensation = Compensation([
            PlannedState(s.tag, s.variable, s.correction, StateCompensator(s.gain, ts=ts, interpolation=interpolation),
                   StateCompensator(s.gain, ts=ts, interpolation=interpolation))
            for s in spec.states])
        self.output = Output(self.csv_path, plan.columns, self.controllers.names, self.compensation.names,
                             [s.tag for s in spec.states], list(spec.outputs),
                             band_tracker(spec, plan.columns))  # the tracked parameters' bands (identify)
        self.read = plan.read_names
        self.ridx = {name: i for i, name in enumerate(self.read)}
        #: the view the row plan was made for, and per output tag: (read index, samples, scored or None, fit)
        self._columns: tuple[Any, list[tuple[int, Any, Any, Any]]] = (None, [])
        self.recovery_until = -math.inf
        self.k = 0
        self.k0 = 0
        self.complete = True
        base = {p.name: p.start for p in spec.parameters}
        base.update(spec.fixed)
        recorded = {**{n: f"parameter:{n}" for n in self.controllers.names},
                    **{n: f"correction:{n}" for n in self.compensation.names}}
        self.twin: Twin | None = None
        self.plain: Twin | None = None
        extrapolate = {p.parameter: p.bounds for p in pairs if isinstance(p.controller, ScaledPI)} \
            if interpolation == "linear" and not continuous else {}
        self.twin = Twin(inputs_twin.fmu if continuous else spec.twin, label="tracked", base=base,
                          inputs=self.view.inputs, tolerance=tolerance, recorded=recorded, extrapolate=extrapolate,
                          rename=inputs_twin.inputs if continuous else None, input_rule=spec.data.inputs)
        if untracked is True:
            try:
                self.plain = Twin(spec.twin, label="untracked", base=base, inputs=self.view.inputs,
                                   tolerance=tolerance,
                                   recorded={n: f"untracked_correction:{n}" for n in self.compensation.names},
                                   input_rule=spec.data.inputs)
            except BaseException:
                self.twin.close()
                raise
        for tw in (self.twin, self.plain):
            if tw is not None:
                tw.steady_start = spec.data.initial == "steady"
                tw.read_names, tw._read_key = self.read, tuple(self.read)
                if self.stream is not None:
                    tw.max_step, tw.replay_inputs = self.stream.max_step, self._replay_inputs
        if not (isinstance(carry, (int, float)) and math.isfinite(carry) and carry >= 0.0):
            raise ValueError(f"carry must be a finite fraction >= 0, got {carry!r}")
        self.carry = float(carry)
        if self.carry > 0.0 and self.twin.me and not continuous:
            self.twin.carry_limits = carry_limits(self.carry, pairs, spec.states, self.ranges)
        #: hold flag of the current sample (given at its start, used by its sub-steps)
        self.hold_k = True
        #: the rows in C (:class:`NativeRows`), made on first use where usable
        self._fast: NativeRows | None = None
        self._fast_checked = False
        #: rows this loop ran in C (its :meth:`run` calls)
        self.native_rows = 0
        self.substeps = 1 if continuous else self._substeps(substeps, interpolation)

    def _substeps(self, substeps: int | Literal["auto"], interpolation: Interpolation) -> int:
        """Sub-steps per sample: the given number, or the automatic choice (see :func:`track`)."""
        assert self.twin is not None
        if substeps == "auto":
            if interpolation != "linear" or not self.twin.me:
                return 1
            try:
                gains = within_sample_gains(self)
            except SimulationError as exc:
                log.warning("the twin failed in the one-sample probe that chooses the sub-steps (%s); "
                            "one step per sample", exc)
                return 1
            return substeps_for(gains)
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
            raise ValueError(f"substeps must be a positive integer or 'auto', got {substeps!r}")
        n = int(substeps)
        if n > 1 and interpolation != "linear":
            raise ValueError("sub-steps integrate the controllers with the twin for an interpolated error: "
                             f"they need interpolation='linear', not {interpolation!r}")
        if n > 1 and not self.twin.me:
            raise ValueError(f"sub-steps need a model-exchange twin (its states restart a resumed run); "
                             f"{self.spec.twin} is co-simulation only")
        return n

    def _native_rows(self) -> NativeRows | None:
        """The fast path for the next rows (made on first use), or None where the rows run in Python."""
        fast = self._fast
        if fast is None:
            if self._fast_checked or not NativeRows.usable(self):
                self._fast_checked = True
                return None
            fast = self._fast = ClosedRows(self) if self.mode == "continuous" else NativeRows(self)
        elif not NativeRows.usable(self):  # the untracked twin was dropped, a twin restarted on the Python path
            return None
        return fast

    # ------------------------------------------------------------------ windows

    def _limit(self) -> int:
        """Rows below this run in the current window: it reaches :data:`MARGIN_ROWS` past them, or to the end."""
        end = self.off + int(self.view.grid.size)
        return end if end >= self.n_rows else end - MARGIN_ROWS

    def _window_for(self, k: int, stop: int | None = None) -> None:
        """Make the current window hold rows *k* .. *stop* - 1 (default: row *k*) to run (a windowed run).

        Else the next window starts at the row before *k*, and the twins' tables with it: a running
        stepper goes on with the new table (:meth:`~trackingbox.fmu.Stepper.replace_inputs`), which
        holds the same rows from the one before *k* to :data:`MARGIN_ROWS` past the window's last row
        run; the solver does not look further than one step (one sample) past a row. A batch of rows
        in C (*stop*: where it would end anyway, at a checkpoint or its row buffer's end) is not cut
        by a window: the continuous mode re-initialises its integrator at every batch.
        """
        stream = self.stream
        if stream is None:
            return
        k = min(max(int(k), 0), self.n_rows - 1)
        stop = k + 1 if stop is None else max(int(stop), k + 1)
        if self.off <= k and stop <= self._limit():
            return
        a = max(0, k - 1)
        view = stream.view(a, min(self.n_rows, a + stream.rows_per_window + MARGIN_ROWS))
        self.plan.view = self.view = view
        self.off = a
        for tw in (self.twin, self.plain):
            if tw is None:
                continue
            tw.inputs = view.inputs
            if self._running and tw.stepper is not None:
                tw.stepper.replace_inputs(view.inputs)

    def _replay_inputs(self, rows: int) -> pd.DataFrame:
        """The twins' input table from row 0 past row *rows* (a replay of a windowed run from the start)."""
        assert self.stream is not None
        return self.stream.view(0, min(self.n_rows, rows + 1 + MARGIN_ROWS)).inputs

    # ------------------------------------------------------------------ state

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue the run from row :attr:`k` (JSON-serialisable after ``jsonify``)."""
        assert self.twin is not None
        rows = self.k
        return {
            "version": CHECKPOINT_VERSION,
            "spec": str(self.spec.path),
            "sample_time": self.ts,
            "columns": self.plan.columns,
            "rows": rows,
            "rows_total": self.n_rows,
            "window": self.window,
            "interpolation": self.interpolation,
            "substeps": self.substeps,
            "carry": self.carry,
            "controllers_mode": self.mode,
            "time": float(self.grid[min(rows, self.n_rows - 1)]),
            "complete": rows >= self.n_rows,
            "parameters": self.controllers.values(),
            "loop": {"recovery_until": self.recovery_until, "hold": self.hold_k,
                     "events": [[e.time, e.kind, e.message] for e in self.events]},
            "controllers": self.controllers.state_dict(),
            "compensation": self.compensation.state_dict(),
            "twin": self.twin.state_dict(),
            "untracked_twin": self.plain.state_dict() if self.plain is not None else None,
            "output": self.output.state_dict(),
        }

    def check_state(self, state: Mapping[str, Any]) -> None:
        """:class:`SpecError` unless *state* was saved by a run of this spec, version and window."""
        if state.get("version") != CHECKPOINT_VERSION or state.get("columns") != self.plan.columns \
                or not math.isclose(float(state.get("sample_time", -1)), self.ts):
            raise SpecError(f"checkpoint {self.ckpt_path} was written for a different spec or version; "
                            "run without --resume to start over")
        if state.get("controllers_mode") != self.mode:
            raise SpecError(f"checkpoint {self.ckpt_path} was written with controllers="
                            f"{state.get('controllers_mode')!r}, not {self.mode!r}; resume with the same mode or "
                            "run without --resume")
        if state.get("substeps") != self.substeps:
            raise SpecError(f"checkpoint {self.ckpt_path} was written with {state.get('substeps')} sub-steps per "
                            f"sample, not {self.substeps}; resume with substeps={state.get('substeps')} or run "
                            "without --resume")
        if state.get("carry") != self.carry:
            raise SpecError(f"checkpoint {self.ckpt_path} was written with carry={state.get('carry')!r}, not "
                            f"{self.carry!r}; resume with the same carry or run without --resume")
        if state.get("interpolation") != self.interpolation:
            raise SpecError(f"checkpoint {self.ckpt_path} was written with interpolation "
                            f"{state.get('interpolation')!r}, not {self.interpolation!r}; run without --resume")
        if state.get("window") != self.window or int(state.get("rows_total", -1)) != self.n_rows:
            raise SpecError(f"checkpoint {self.ckpt_path} was written for window {state.get('window')!r} "
                            f"({state.get('rows_total')} rows), not {self.window!r} ({self.n_rows} rows); resume "
                            f"with --window {state.get('window')} or run without --resume")

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Continue from a saved state: each part restores its own; the twins from states or a replay."""
        assert self.twin is not None
        self.check_state(state)
        self.k = self.k0 = int(state["rows"])
        self.output.load_state_dict(state["output"])
        self.controllers.load_state_dict(state["controllers"])
        self.compensation.load_state_dict(state["compensation"])
        self.recovery_until = float(state["loop"]["recovery_until"])
        self.hold_k = bool(state["loop"]["hold"])
        for e in state["loop"].get("events", []):
            self.events.append(TrackingEvent(float(e[0]), str(e[1]), str(e[2])))
        t_k = float(self.grid[self.k0]) if self.k0 < self.n_rows else float(self.grid[-1])
        self._window_for(self.k0)
        self.twin.load_state_dict(state["twin"], t=t_k, csv_path=self.csv_path, rows=self.k0, grid=self.grid,
                                  substeps=self.substeps)
        if self.plain is not None:
            self.plain.load_state_dict(state["untracked_twin"] or {"x": None}, t=t_k, csv_path=self.csv_path,
                                       rows=self.k0, grid=self.grid)
        self._running = True
        log.info("resumed at row %d (t = %g s) from %s", self.k0, t_k, self.ckpt_path)

    # ------------------------------------------------------------------ running

    def begin(self, *, resume: bool = False) -> None:
        """Start fresh, or from ``checkpoint.json`` when *resume* and there is one."""
        assert self.twin is not None
        self._begin(resume)
        if self.mode == "continuous" and not ClosedRows.usable(self):
            reason = self.twin.model.native_reason or (
                f"{NATIVE_ROWS_ENV}=0" if not config.get("native_rows")
                else "the twins do not run on the native stepper")
            raise SimulationError(f"controllers='continuous' integrates the controllers in the native stepper's "
                                  f"right-hand side, which is not to be had here: {reason}")

    def _begin(self, resume: bool) -> None:
        assert self.twin is not None
        if resume and self.ckpt_path.exists():
            # sealed: a corrupt or truncated checkpoint, or a CSV that is not the one it vouches for, is refused
            self.load_state_dict(unjsonify(self._ckpt.read()))
            return
        if resume:
            log.info("no checkpoint in %s; starting from the beginning", self.out_dir)
        corrections = {c: 0.0 for c in self.compensation.names}
        self.twin.start(0.0, {**self.controllers.values(), **corrections})
        if self.plain is not None:
            self.plain.start(0.0, dict(corrections))
        self._running = True
        self.output.open()

    def extend(self, view: MeasurementView | None = None) -> None:
        """Go on over a longer measurement view: data that arrived while the loop ran (the online mode).

        A loop made with a growing ``stream`` takes no view: it goes on over the stream's rows
        (its ``n_rows`` grew), read window by window as a windowed run reads them.

        *view* must have the current grid as its prefix (same start and
        ``sample_time``; built as in :func:`track`). The rows still to run read
        their samples from it, and the twins restart at the current row from
        their states (or a replay), as at a checkpoint, with *view*'s longer
        input table. Drive the loop sample by sample with ``extend`` then
        ``run(max_steps=...)`` over the rows whose next sample has arrived.
        """
        if self.stream is not None:
            if view is None and hasattr(self.stream, "grow"):
                self.output.flush()
                self.grid, self.n_rows = self.stream.grid, self.stream.n_rows
                return
            raise DataError("extend() goes on over a longer measurement view: start the loop with view= "
                            "(the whole view), not from the spec's file window by window")
        if view is None:
            raise DataError("extend() needs the longer measurement view (or a loop made with a growing stream)")
        n = self.n_rows
        if view.grid.size < n or not np.array_equal(view.grid[:n], self.grid) or view.skip != self.view.skip:
            raise DataError(f"the measurement view given to extend() does not continue the grid of "
                            f"{self.view.source.name} ({n} rows of {self.ts:g} s from 0)")
        self.output.flush()
        self.plan.view = self.view = view
        self.grid, self.n_rows = view.grid, view.grid.size
        t_k = float(self.grid[min(self.k, self.n_rows - 1)])
        for tw in (self.twin, self.plain):
            if tw is None:
                continue
            tw.inputs = view.inputs
            if tw.me and tw.x is not None and math.isclose(tw.x_time, t_k, abs_tol=1e-9 * max(1.0, t_k)):
                if tw.carry_limits and tw.stepper is not None and tw.stepper.time == tw.x_time:
                    # its integrator stopped at t_k and never saw past the old table: it goes on
                    # (carried), so the run is the one an offline run over the whole view makes
                    tw.stepper.extend_inputs(view.inputs)
                else:
                    tw.start(t_k, dict(tw.applied), tw.x)
            else:
                tw.replay_csv(self.csv_path, self.k, self.grid)

    def checkpoint(self) -> None:
        """Write :meth:`state_dict` to ``checkpoint.json``, atomically."""
        self._ckpt.write(jsonify(self.state_dict()))

    def event(self, t: float, kind: str, message: str, level: int = logging.WARNING) -> None:
        log.log(level, "t = %g s: %s", t, message)
        if len(self.events) < 1000:
            self.events.append(TrackingEvent(float(t), kind, message))

    def _step_tracked(self, k: int, values: dict[str, float], resume: tuple[int, int] | None = None) -> bool:
        """Step the tracked twin from row k to k+1, with the controllers on it at every sub-step.

        With :attr:`substeps` ``n > 1`` the sample is cut into ``n`` equal
        parts; after each (but the last, which row k+1 takes) the controllers
        read the twin and advance with the measurement interpolated, and the
        twin gets their new values: the box's continuous loop, sampled ``n``
        times finer. True if the twin had to recover from a solver failure
        (the controllers then stay as they are for the rest of the sample).

        *resume* ``(j, code)``: a batch of rows (:class:`NativeRows`) stepped
        the sub-steps before ``j`` and the ``tbn_advance`` of sub-step ``j``
        returned *code*; go on from there.
        """
        assert self.twin is not None
        n = self.substeps
        j0, code = resume if resume is not None else (1, None)
        if n == 1:
            return self._safe_step(self.twin, k, values, code=code)
        t_k, t_next = float(self.grid[k]), float(self.grid[k + 1])
        h = (t_next - t_k) / n
        t_from = t_k if j0 == 1 else t_k + (j0 - 1) * h
        if j0 > 1:
            values = {**values, **self.controllers.values()}
        recovered = False
        for j in range(j0, n + 1):
            t_to = t_next if j == n else t_k + j * h
            recovered = self._safe_step(self.twin, k, values, t_from, t_to, code=code) or recovered
            code = None
            t_from = t_to
            if j < n and not recovered:
                y = self.twin.get(self.read)
                self.controllers.substep(t_to, j / n, k - self.off, y, self.ridx, self.view, self.hold_k)
                values = {**values, **self.controllers.values()}
        return recovered

    def _safe_step(self, tw: Twin, k: int, values: dict[str, float], t_from: float | None = None,
                   t_to: float | None = None, code: int | None = None) -> bool:
        """Step *tw* from row k to k+1 (or *t_from* to *t_to* within); recover from a solver failure.

        True if it had to recover. *code*: the step's ``tbn_advance`` already
        returned it (see :meth:`Twin.step`).
        """
        grid = self.grid
        t_k = float(grid[k])
        t_from = t_k if t_from is None else t_from
        t_next = float(grid[k + 1]) if t_to is None else t_to
        try:
            tw.step(t_next, values, code)
            return False
        except SimulationError as exc:
            self.event(t_from, "solver-failure",
                       f"{tw.label} twin failed between {t_from:g} s and {t_next:g} s: {exc}")
        self.output.flush()
        try:
            if tw.me and tw.x is not None and math.isclose(tw.x_time, t_from, abs_tol=1e-9 * max(1.0, t_from)):
                tw.start(t_from, values, tw.x)
            else:
                tw.replay_csv(self.csv_path, k, grid)
                tw.stepper.set(tw.fmu_values(values))
                tw.applied.update(values)
                if t_from > t_k:
                    tw.step(t_from, values)
            tw.step(t_next, values)
            self.event(t_from, "recovered",
                       f"{tw.label} twin re-initialised from its state at {t_from:g} s and continued")
            return True
        except SimulationError as exc:
            self.event(t_from, "solver-failure", f"{tw.label} twin failed again after re-initialisation: {exc}")
        tw.start(t_from, values)  # cold start: fresh initialisation at t_from
        tw.step(t_next, values)  # a third failure propagates
        self.event(t_from, "cold-start", f"{tw.label} twin cold-started (fresh initialisation) at {t_from:g} s")
        return True

    def _row(self, k: int) -> tuple[dict[str, float], dict[str, float]]:
        """Read the twins, update the controllers and compensation, write row *k*.

        Returns the values to apply to the tracked twin (parameters and
        corrections) and to the untracked one (its corrections).
        """
        assert self.twin is not None
        view, plan, read, ridx = self.view, self.plan, self.read, self.ridx
        t = float(self.grid[k])
        y = self.twin.get(read)
        yu = self.plain.get(read) if self.plain is not None else (
            np.array([plan.untracked_table[n][k] for n in read]) if plan.untracked_table is not None
            else np.full(len(read), np.nan))
        i = k - self.off  # row k in the current window
        hold_all = t < self.hold_until - 1e-9 or bool(view.stopped[i]) or t < self.recovery_until - 1e-9
        if hold_all != self.hold_k:
            self.twin.force_restart = True  # entering or leaving a hold: the integrator restarts
        self.hold_k = hold_all
        modes = self.controllers.update(t, i, y, ridx, view, hold_all, self.event)
        for s in self.compensation.states:
            self.output.sstats[s.tag].add(float(y[ridx[s.variable]]))
        corr, corr_u = self.compensation.update(i, y, yu if self.plain is not None else None, ridx, view)
        params = self.controllers.values()
        row: list[Any] = [t]
        if self._columns[0] is not view:
            fits = self.output.fits
            self._columns = (view, [(ridx[plan.tag_var[tag]], view.samples[tag],
                                     view.scored[tag] if tag in fits else None, fits.get(tag))
                                    for tag in plan.out_tags])
        yl, yul = y.tolist(), yu.tolist()  # Python floats, as float() of the elements
        for j, samples, scored, fit in self._columns[1]:
            m = float(samples[i])
            a, b = yl[j], yul[j]
            row += (m, a, b)
            if scored is not None and scored[i]:
                fit.add(m, a, b)
        row += [params[n] for n in self.controllers.names]
        row += [corr[n] for n in self.compensation.names]
        row += [corr_u[n] for n in self.compensation.names]
        row += modes
        self.output.write(row)
        for n in self.controllers.names:
            self.output.pstats[n].add(params[n])
        for n in self.compensation.names:
            self.output.cstats[n].add(corr[n])
        return {**params, **corr}, corr_u

    def run(self, *, max_steps: int | None = None, progress: Callable[[int, int], None] | None = None) -> bool:
        """Step to the end (or *max_steps* rows); checkpoint on the way and at the end. True if complete."""
        assert self.twin is not None
        n_rows = self.n_rows
        rows_this_call = 0
        self.complete = True
        every = self.checkpoint_every
        while self.k < n_rows:
            k = self.k
            self._window_for(k)
            fast = self._native_rows() if k < n_rows - 1 else None
            if fast is not None:
                k_stop = min(n_rows - 1, (k // every + 1) * every)
                if max_steps is not None:
                    k_stop = min(k_stop, k + max_steps - rows_this_call)
                self._window_for(k, min(k_stop, k + fast.CAP))
                k_stop = min(k_stop, self._limit())
                written, pending, python = fast.run(self, k, k_stop)
                if progress is not None:
                    for j in range(written):
                        progress(k + j + 1, n_rows)
                rows_this_call += written
                self.native_rows += written
                if pending is not None:  # a twin's step inside the last row written needs Python
                    self._step_row(self.k, *pending)
                elif written and self.k % every == 0:
                    self._restart_point()
                if max_steps is not None and rows_this_call >= max_steps and self.k < n_rows:
                    self.complete = False
                    break
                if not python:
                    continue
                k = self.k  # the row that needs Python (a tag going missing or coming back, ...)
                self._window_for(k)
            values, corr_u = self._row(k)
            rows_this_call += 1
            if progress is not None:
                progress(k + 1, n_rows)
            if k == n_rows - 1:
                self.k += 1
                break
            self._step_row(k, values, corr_u)
            if max_steps is not None and rows_this_call >= max_steps and self.k < n_rows:
                self.complete = False
                break
        self.checkpoint()
        return self.complete

    def _step_row(self, k: int, values: dict[str, float], corr_u: dict[str, float],
                  resume: tuple[int, int, int] | None = None) -> None:
        """Step both twins from row k to k+1 (row k written) and move on to row k+1 (checkpoint on the way).

        *resume* ``(twin, j, code)``: a batch of rows stepped part of this row
        and the ``tbn_advance`` of the tracked (``twin`` 0, sub-step ``j``) or
        the untracked twin (1) returned *code*: go on from there.
        """
        which, j, code = resume if resume is not None else (-1, 1, None)
        recovered = False
        if which != 1:
            recovered = self._step_tracked(k, values, (j, code) if which == 0 else None)
        if self.plain is not None:
            try:
                self._safe_step(self.plain, k, dict(corr_u), code=code if which == 1 else None)
            except SimulationError as exc:
                # the comparison run is not worth stopping the tracking for
                self.event(float(self.grid[k]), "untracked-abandoned", f"untracked twin failed for good and "
                           f"is dropped (its columns are empty from here on): {exc}")
                self.plain.close()
                self.plain = None
        if recovered:
            self.recovery_until = float(self.grid[k + 1]) + self.recovery_hold
            self.event(float(self.grid[k]), "hold",
                       f"controllers on hold until t = {self.recovery_until:g} s after the recovery")
        self.k += 1
        if self.k % self.checkpoint_every == 0:
            self._restart_point()

    def _restart_point(self) -> None:
        """Checkpoint at row :attr:`k` and restart the twins there from their saved states."""
        self.checkpoint()
        # a checkpoint is a restart point: re-initialise from the saved states, exactly
        # as a resume would, so a resumed run is identical to an uninterrupted one
        for tw in (self.twin, self.plain):
            if tw is not None and tw.me and tw.x is not None:
                tw.start(float(self.grid[self.k]), dict(tw.applied), tw.x)

    def close(self) -> None:
        """Close the CSV and both twins."""
        self.output.close()
        for tw in (self.twin, self.plain):
            if tw is not None:
                tw.close()
        if self.stream is not None:
            self.stream.close()

    # ------------------------------------------------------------------ result

    def result(self) -> TrackingResult:
        """The run's :class:`TrackingResult` (also written to ``result.json``)."""
        grid, k, k0, ts = self.grid, self.k, self.k0, self.ts
        metric = self.view.window
        out = self.output
        restarts, carried = self.twin.counts() if self.twin is not None else (0, 0)
        result = TrackingResult(
            csv=self.csv_path,
            window=(max(metric[0], self.hold_until), min(metric[1], float(grid[-1]) + ts)),
            variables={t: f.result() for t, f in out.fits.items()},
            parameters={n: ParameterResult(s.final, s.min, s.max, p.bounds[0], p.bounds[1])
                        for (n, s), p in zip(out.pstats.items(), self.controllers.pairs)},
            corrections={n: ParameterResult(s.final, s.min, s.max, math.nan, math.nan)
                         for n, s in out.cstats.items()},
            states={n: ParameterResult(s.final, s.min, s.max, math.nan, math.nan) for n, s in out.sstats.items()},
            seconds=_time.perf_counter() - self.wall0,
            seconds_untracked=self.plain.step_seconds if self.plain is not None else math.nan,
            simulated_seconds=float(grid[min(k, self.n_rows - 1)] - grid[k0]) if k > k0 else 0.0,
            steps=k,
            complete=self.complete,
            events=tuple(self.events),
            restarts=restarts,
            carried=carried,
        )
        summary = {**result.to_json(), "complete": self.complete, "steps": k, "csv": str(self.csv_path),
                   "window": list(result.window),
                   "variables_detail": {t: {"samples": v.samples} for t, v in result.variables.items()},
                   "corrections": {n: {"final": num(c.final), "min": num(c.min), "max": num(c.max)}
                                   for n, c in result.corrections.items()},
                   "states": {n: {"final": num(c.final), "min": num(c.min), "max": num(c.max)}
                              for n, c in result.states.items()},
                   "events": [[e.time, e.kind, e.message] for e in self.events],
                   "integrator": {"restarts": restarts, "carried": carried},
                   **({"bands": out.bands.describe()} if out.bands is not None else {})}
        write_text_atomic(self.out_dir / RESULT_NAME, json.dumps(summary, indent=1))
        return result
