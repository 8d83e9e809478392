"""The loop's fast path: batches of tracking rows stepped in C (:class:`NativeRows`).

When both twins run on :class:`~trackingbox.fmu.NativeStepper` with ScaledPI controllers and the
``"linear"`` error, a batch of rows (controllers, compensation, both twins' steps, the row
values and the summaries) runs in one C call (``tbn_track_rows``); :class:`ClosedRows` also
integrates the controllers with the twin (the continuous mode).
"""
from __future__ import annotations

import ctypes
import logging
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import config, native
from ..fmu import NativeStepper
from .controllers import ScaledPI
from .twin import Twin

if TYPE_CHECKING:
    from .loop import TrackingLoop

log = logging.getLogger(__name__)



# --------------------------------------------------------------------------- the loop's fast path

#: environment variable: ``0`` keeps the tracking loop on its Python path (no :class:`NativeRows`)
NATIVE_ROWS_ENV = config.setting("native_rows").env


def pointers(arrays: Sequence[Any], ctype: Any) -> Any:
    """A C array of the data pointers of *arrays* (None: a null pointer)."""
    ptr = ctypes.POINTER(ctype)
    return (ptr * max(len(arrays), 1))(*(a.ctypes.data_as(ptr) if a is not None else ptr() for a in arrays))


class NativeRows:
    """The loop's rows in C: ``tbn_track_rows`` of the native stepper's library (issue 12).

    Over a batch of rows it does what :meth:`TrackingLoop._row`,
    :meth:`~TrackingLoop._step_tracked` and :meth:`Twin.step` do (the PI
    laws with their clamped integration, the sub-steps, the state
    compensation, the CSV row's values, the summaries, both twins' sets,
    steps and reads through ``tbn_advance``), with the same arithmetic in the
    same order, so the rows are the Python path's, byte for byte. It hands
    back to the Python path at the first row that needs it (a tag going
    missing or coming back), inside a row whose twin step did not end
    normally (an event, a failure: :meth:`TrackingLoop._step_row` finishes
    that step as the Python path would have), at a checkpoint, at the batch's
    row limit and before the last row.

    Usable (:meth:`usable`) when every pair is a :class:`ScaledPI` on the
    ``"linear"`` error, both twins run on :class:`~trackingbox.native.NativeStepper`
    (or there is no untracked twin and no untracked table) and
    ``TRACKINGBOX_NATIVE_ROWS`` is not ``0``. Every batch first checks its
    twins (:meth:`NativeStepper.rows_ready <trackingbox.native.NativeStepper.rows_ready>`).
    """

    #: rows per batch at most (the row buffer)
    CAP = 512

    def __init__(self, loop: TrackingLoop) -> None:
        self.native = native
        self.lib = native.library()
        self.b = native.TrackBatch()
        self.view: Any = None
        ctl, comp, plan = loop.controllers, loop.compensation, loop.plan
        self.npairs, self.nstates = len(ctl.pairs), len(comp.states)
        self.names = [list(ctl.names) + list(comp.names), list(comp.names)]
        ridx = loop.ridx
        self.pidx = (ctypes.c_size_t * max(self.npairs, 1))(*(ridx[p.fmu_name] for p in ctl.pairs))
        self.sidx = (ctypes.c_size_t * max(self.nstates, 1))(*(ridx[s.variable] for s in comp.states))
        self.tidx = (ctypes.c_size_t * max(len(plan.out_tags), 1))(*(ridx[plan.tag_var[t]] for t in plan.out_tags))
        self.ncols = len(plan.columns)
        self.rows = np.zeros((self.CAP, self.ncols))
        self.mode_cols = list(range(self.ncols - self.npairs, self.ncols))
        self.pi = np.zeros((max(self.npairs, 1), len(native.PI_FIELDS)))
        self.comp = np.zeros((2, max(self.nstates, 1), len(native.SC_FIELDS)))
        self.fits = np.zeros((max(len(plan.out_tags), 1), 7))
        self.stats = [np.zeros((max(n, 1), 3)) for n in (self.npairs, self.nstates, self.nstates)]
        self.missing = np.zeros(max(self.npairs, 1), dtype=np.intc)
        self.io: list[dict[str, Any]] = []
        b = self.b
        b.substeps, b.ts = loop.substeps, loop.ts
        b.hold_until = loop.hold_until
        b.npairs, b.nstates, b.ntags, b.nread = self.npairs, self.nstates, len(plan.out_tags), len(loop.read)
        b.pidx, b.sidx, b.tidx = self.pidx, self.sidx, self.tidx
        b.pi = self.pi.ctypes.data_as(native.PD)
        b.comp_t = self.comp[0].ctypes.data_as(native.PD)
        b.comp_u = self.comp[1].ctypes.data_as(native.PD)
        b.fits = self.fits.ctypes.data_as(native.PD)
        b.pstats, b.cstats, b.sstats = (a.ctypes.data_as(native.PD) for a in self.stats)
        b.missing = self.missing.ctypes.data_as(native.PINT)
        b.rows, b.ncols, b.cap = self.rows.ctypes.data_as(native.PD), self.ncols, self.CAP
        for which in (0, 1):
            nv = len(self.names[which])
            io = {"applied": np.zeros(max(nv, 1)), "given": np.zeros(max(nv, 1)),
                  "given_ok": np.zeros(max(nv, 1), dtype=np.intc), "ever_set": np.zeros(max(nv, 1), dtype=np.intc),
                  "limit": np.full(max(nv, 1), math.nan), "extrap": np.zeros(max(nv, 1), dtype=np.intc),
                  "lo": np.zeros(max(nv, 1)), "hi": np.zeros(max(nv, 1)), "y": np.zeros(max(len(loop.read), 1)),
                  "val": np.zeros(max(nv, 1)), "sub": np.zeros(max(nv, 1)),
                  "sub_vr": (ctypes.c_uint32 * max(nv, 1))(), "sub_idx": (ctypes.c_size_t * max(nv, 1))()}
            t = b.tw[which]
            t.nv = nv
            for name in ("applied", "given", "limit", "lo", "hi", "y", "val", "sub"):
                setattr(t, name, io[name].ctypes.data_as(native.PD))
            for name in ("given_ok", "ever_set", "extrap"):
                setattr(t, name, io[name].ctypes.data_as(native.PINT))
            t.sub_vr, t.sub_idx = io["sub_vr"], io["sub_idx"]
            self.io.append(io)

    @staticmethod
    def usable(loop: TrackingLoop) -> bool:
        """True if the loop's rows can run in C (see the class docstring)."""
        if not config.get("native_rows") or loop.interpolation != "linear":
            return False
        if not all(isinstance(p.controller, ScaledPI) for p in loop.controllers.pairs):
            return False
        if not isinstance(loop.twin.stepper if loop.twin is not None else None, NativeStepper):
            return False
        if loop.plain is None:
            return loop.plan.untracked_table is None
        return isinstance(loop.plain.stepper, NativeStepper)

    def _set_view(self, loop: TrackingLoop) -> None:
        """The measurement view's arrays (again after :meth:`TrackingLoop.extend`)."""
        view, plan, b = loop.view, loop.plan, self.b
        fits = loop.output.fits
        self.grid = np.ascontiguousarray(view.grid, dtype=float)
        self.stopped = np.ascontiguousarray(view.stopped, dtype=np.uint8)
        samples = {t: np.ascontiguousarray(view.samples[t], dtype=float) for t in
                   {*(p.tag for p in loop.controllers.pairs), *(s.tag for s in loop.compensation.states),
                    *plan.out_tags}}
        self.samples = samples
        self.scored = [np.ascontiguousarray(view.scored[t], dtype=np.uint8) if t in fits else None
                       for t in plan.out_tags]
        b.grid = self.grid.ctypes.data_as(self.native.PD)
        b.stopped = self.stopped.ctypes.data_as(ctypes.POINTER(ctypes.c_ubyte))
        self.psamples = pointers([samples[p.tag] for p in loop.controllers.pairs], ctypes.c_double)
        self.ssamples = pointers([samples[s.tag] for s in loop.compensation.states], ctypes.c_double)
        self.tsamples = pointers([samples[t] for t in plan.out_tags], ctypes.c_double)
        self.pscored = pointers(self.scored, ctypes.c_ubyte)
        b.psamples, b.ssamples, b.tsamples, b.scored = self.psamples, self.ssamples, self.tsamples, self.pscored
        self.view = view

    # ------------------------------------------------------------------ state to C and back

    def _twin_in(self, which: int, tw: Twin | None, read: list[str]) -> bool:
        """The twin's state into ``tw[which]``; False if its stepper cannot take a batch now."""
        t = self.b.tw[which]
        if tw is None:
            t.h = None
            return True
        st = tw.stepper
        names = self.names[which]
        if not tw.me or tw.read_names is None or any(n not in tw.applied for n in names):
            return False
        ready = st.rows_ready([tw.fmu_name(n) for n in names], read)
        if ready is None:
            return False
        out, vrs, is_param = ready
        io = self.io[which]
        nv = len(names)
        io["vr"] = (ctypes.c_uint32 * max(nv, 1))(*vrs)
        io["is_param"] = (ctypes.c_int * max(nv, 1))(*is_param)
        t.vr, t.is_param = io["vr"], io["is_param"]
        t.out = out.ctypes.data_as(self.native.PD)
        io["out"] = out
        for i, n in enumerate(names):
            io["applied"][i] = tw.applied[n]
            g = tw.given.get(n)
            io["given_ok"][i] = g is not None
            io["given"][i] = g if g is not None else 0.0
            io["limit"][i] = tw.carry_limits.get(n, math.nan)
            bounds = tw.extrapolate.get(n)
            io["extrap"][i] = bounds is not None
            if bounds is not None:
                io["lo"][i], io["hi"][i] = bounds
        io["ever_set"][:] = 0
        t.carry_any = 1 if tw.carry_limits else 0
        t.force_restart = 1 if tw.force_restart else 0
        t.exact = 1 if st._solver.exact else 0
        t.time = st.time
        t.carried = t.restarts = 0
        t.seconds = 0.0
        y = tw.y if tw.y is not None else st.get(read)
        io["y"][: len(read)] = y
        io["time0"] = st.time
        t.h = st._handle
        return True

    def _twin_out(self, which: int, tw: Twin | None) -> None:
        """``tw[which]``'s state back into the twin and its stepper."""
        if tw is None:
            return
        t, io, st = self.b.tw[which], self.io[which], tw.stepper
        names = self.names[which]
        applied, given = io["applied"].tolist(), io["given"].tolist()
        for i, n in enumerate(names):
            tw.applied[n] = applied[i]
        if names and io["given_ok"][0]:
            tw.given = {n: given[i] for i, n in enumerate(names)}
        tw.force_restart = bool(t.force_restart)
        tw.step_seconds += t.seconds
        moved = t.time != io["time0"]
        st.rows_done(t.time, t.carried, t.restarts,
                     {tw.fmu_name(n): applied[i] for i, n in enumerate(names) if io["ever_set"][i]})
        if moved:
            tw.x = st._x[: st._nx].copy()
            tw.x_time = float(t.time)
            tw.y = io["y"][: self.b.nread].copy()

    def _state_in(self, loop: TrackingLoop) -> None:
        for i, p in enumerate(loop.controllers.pairs):
            c = p.controller
            sc = c.scaling
            self.pi[i] = (c.u, c.e_mem if c.e_mem is not None else 0.0, c.e_mem is not None,
                          c.e_last if c.e_last is not None else 0.0, c.e_last is not None, c.hold_last,
                          c.direction * c.kp, c.ti, c.te, sc.span, sc.p_min, sc.p_max, c.mode == "hold")
            self.missing[i] = loop.controllers.missing[p.tag] is not None
        for i, s in enumerate(loop.compensation.states):
            for j, c in enumerate((s.tracked, s.untracked)):
                self.comp[j, i] = (c.m, c.e_mem if c.e_mem is not None else 0.0, c.e_mem is not None,
                                   c.e_last if c.e_last is not None else 0.0, c.e_last is not None, c.hold_last,
                                   c.gain, c.ts, c.te, c.mode == "hold")
        out = loop.output
        for i, tag in enumerate(loop.plan.out_tags):
            fit = out.fits.get(tag)
            if fit is not None:
                self.fits[i] = fit.state()
        for arr, stats in zip(self.stats, (out.pstats, out.cstats, out.sstats)):
            for i, st in enumerate(stats.values()):
                arr[i] = st.state()
        b = self.b
        b.hold_k = 1 if loop.hold_k else 0
        last = loop.controllers.last_time
        b.has_last_time = last is not None
        b.last_time = last if last is not None else 0.0
        b.recovery_until = loop.recovery_until

    def _state_out(self, loop: TrackingLoop) -> None:
        def memory(row: Any, c: Any) -> None:
            c.e_mem = row[1] if row[2] else None
            c.e_last = row[3] if row[4] else None
            c.hold_last = bool(row[5])
            c.mode = "hold" if row[-1] else "auto"

        for p, row in zip(loop.controllers.pairs, self.pi.tolist()):
            p.controller.u = row[0]
            memory(row, p.controller)
        for i, s in enumerate(loop.compensation.states):
            for j, c in enumerate((s.tracked, s.untracked)):
                row = self.comp[j, i].tolist()
                c.m = row[0]
                memory(row, c)
        out = loop.output
        for i, tag in enumerate(loop.plan.out_tags):
            fit = out.fits.get(tag)
            if fit is not None:
                fit.restore(self.fits[i].tolist())
        for arr, stats in zip(self.stats, (out.pstats, out.cstats, out.sstats)):
            for i, st in enumerate(stats.values()):
                st.restore(arr[i].tolist())
        b = self.b
        loop.hold_k = bool(b.hold_k)
        if b.has_last_time:
            loop.controllers.last_time = b.last_time

    # ------------------------------------------------------------------ a batch

    def _rows(self, loop: TrackingLoop) -> None:
        """The C call of a batch (its state is in :attr:`b`)."""
        self.lib.tbn_track_rows(ctypes.byref(self.b))

    def run(self, loop: TrackingLoop, k: int, k_stop: int
            ) -> tuple[int, tuple[dict[str, float], dict[str, float], tuple[int, int, int]] | None, bool]:
        """Rows *k* .. at most *k_stop* - 1 in C: ``(rows written, pending, python)``.

        :attr:`TrackingLoop.k` moves past the rows that were written and
        stepped. *pending*: the last row written was not stepped to its end:
        ``(values, corrections of the untracked twin, (twin, sub-step, code))``
        for :meth:`TrackingLoop._step_row`. *python*: the row at
        :attr:`TrackingLoop.k` needs the Python path.
        """
        if self.view is not loop.view:
            self._set_view(loop)
        read = loop.read
        if not (self._twin_in(0, loop.twin, read) and self._twin_in(1, loop.plain, read)):
            return 0, None, True
        self._state_in(loop)
        b = self.b
        b.k0, b.k_stop = k - loop.off, k_stop - loop.off  # rows of the current window
        self._rows(loop)
        self._twin_out(0, loop.twin)
        self._twin_out(1, loop.plain)
        self._state_out(loop)
        done = int(b.done)
        interrupted = b.status == self.native.ROWS_INTERRUPTED
        written = done + (1 if interrupted else 0)
        if written:
            text = self.native.format_rows(self.rows[:written], self.npairs)
            if text is not None:
                loop.output.write_text(text, self.rows[:written])
            else:
                rows = self.rows[:written].tolist()
                for row in rows:
                    for c in self.mode_cols:
                        row[c] = "hold" if row[c] else "auto"
                loop.output.writerows(rows)
        loop.k = k + done
        pending = None
        if interrupted:
            row = self.rows[written - 1].tolist()
            np_, ns = self.npairs, self.nstates
            first = self.ncols - np_ - 2 * ns - np_
            params = row[first: first + np_]
            corr = row[first + np_: first + np_ + ns]
            corr_u = row[first + np_ + ns: first + np_ + 2 * ns]
            names = self.names[0]
            values = dict(zip(names, params + corr))
            pending = (values, dict(zip(self.names[1], corr_u)), (int(b.which), int(b.sub), int(b.code)))
        return written, pending, b.status == self.native.ROWS_PYTHON


#: Nominal values of the controllers' states in the continuous mode, as a multiple of their range:
#: a PI controller's output and error memory get ``CLOSED_RANGE_FACTOR * 100 %`` (the output's full
#: range), a compensator's error memory the factor times its level's measured range and its
#: correction the factor times the gain times that range; their absolute tolerance is the twin's
#: rtol times these. Measured against the same mode at rtol 1e-10 (rtol 1e-6): heat exchanger (3 h)
#: factor 1 gives 6.8e-6 of the parameter's range and 1.2e-5 / 4.5e-5 of the tags' ranges at 1.7x
#: the integrator CPU of factor 10, which gives 4.3e-5 and 4.2e-5 / 6.8e-5 (the discrete path: 2.4e-4
#: and 2.1e-4 / 3.5e-4 from the same reference); factor 100 went to 5.1e-4 of the parameter's range
#: (without stops at the samples). Heat production (2 h, three pairs, three levels): factor 10 on the
#: compensators too takes 30 % less integrator CPU than 1 and keeps every tag, parameter and
#: correction within 6.1e-5 of its range (LI-400; factor 1: 1e-5).
CLOSED_RANGE_FACTOR = 10.0


class ClosedRows(NativeRows):
    """The loop's rows with the controllers inside the integrated system: ``tbn_closed_rows`` (issue 12).

    Each pair's PI law (:class:`~trackingbox.tracking.controllers.ScaledPI`'s
    continuous form, the compiled box's ``Blocks.ParameterController``) and
    each level's compensator (``Blocks.StateCompensation``) are continuous
    states that CVODE integrates with the twin's states in one right-hand side,
    which reads the measurement interpolated linearly between samples and
    sets the parameters and corrections as the twin's Real *inputs*. The
    untracked twin runs the same way with its compensators. CVODE stops at
    every sample (its stop time, where the interpolated data have their kinks;
    no re-initialisation) and is re-initialised only at the start of a batch
    (a checkpoint, the row buffer's end) and where a hold starts or ends or a
    tag goes missing or comes back. Between batches the controllers are
    handed to and from their discrete form (``u``, the error memory), so a row
    that needs Python (a tag going missing or coming back, a solver failure)
    runs on the discrete path and the next batch goes on from it.
    """

    def __init__(self, loop: TrackingLoop) -> None:
        super().__init__(loop)
        ctl, comp = loop.controllers, loop.compensation
        tw = loop.twin
        assert tw is not None
        self.set_names = [[tw.fmu_name(n) for n in ctl.names] + list(comp.names), list(comp.names)]
        self.sim_names = [[p.fmu_name for p in ctl.pairs] + [s.variable for s in comp.states],
                          [s.variable for s in comp.states]]
        level_nominal = []
        for s_ in comp.states:
            n, lo, hi = loop.ranges[s_.tag]
            rng = float(hi - lo) if n >= 2 else 0.0
            rng = CLOSED_RANGE_FACTOR * (rng if rng > 0.0 else 1.0)
            level_nominal += [rng, max(abs(float(s_.tracked.gain)) * rng, 1e-12)]
        #: nominal values of the controllers' states (absolute tolerance: the twin's rtol times these),
        #: see :data:`CLOSED_RANGE_FACTOR`
        pi_nominal = CLOSED_RANGE_FACTOR * 100.0
        self.nominal = [[pi_nominal, pi_nominal] * len(ctl.pairs) + level_nominal, level_nominal]

    def _rows(self, loop: TrackingLoop) -> None:
        handles = []
        for which, tw in enumerate((loop.twin, loop.plain)):
            if tw is None:
                handles.append(None)
                continue
            handles.append(tw.stepper.closed(len(loop.controllers.pairs) if which == 0 else 0,
                                             self.set_names[which], self.sim_names[which], self.nominal[which]))
        self.lib.tbn_closed_rows(ctypes.byref(self.b), self.grid.size, handles[0], handles[1])
        for io in self.io:
            io["ever_set"][:] = 1  # the inputs hold the values at the twin's time

    def _state_out(self, loop: TrackingLoop) -> None:
        super()._state_out(loop)
        loop.controllers.last_time = None  # nothing is left to integrate up to the twin's time
