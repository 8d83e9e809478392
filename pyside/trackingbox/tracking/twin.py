"""One twin of a tracking run: the FMU, its stepper, the values applied and the variables read.

:class:`Twin` is the tracked twin and, in lockstep, the untracked one; it saves and restores its
own state (``state_dict`` / ``load_state_dict``) and recovers from a solver failure.
"""
from __future__ import annotations

import logging
import math
import time as _time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..fmu import NativeStepper
from ..simulation.models import open_model
from .plan import read_rows

if TYPE_CHECKING:
    pass

log = logging.getLogger(__name__)



# --------------------------------------------------------------------------- the twin

#: The twins' native steppers reuse CVODE's last Jacobian for the first step after a restart
#: (:meth:`~trackingbox.native.NativeStepper.keep_jacobian`) instead of evaluating a new one, one
#: right-hand side per state (29 on heat production). Measured 2026-11-27, heat production, 1 day,
#: 8 sub-steps (right-hand-side evaluations of the tracked twin, tracking run alone): the default
#: (carried) path 609k -> 358k, the restart path (``carry=0``) 2.79M -> 0.86M; the plain twin run
#: makes 188k. Not after a forced restart (a hold's edges, a recovery: large changes), where a new one
#: is evaluated (:meth:`~trackingbox.native.NativeStepper.forget_jacobian`), so a run whose only restarts
#: are those (the heat exchanger) is unchanged bit for bit. Accuracy (2 h case of ``tests/test_tracking_carry.py`` at rtol 1e-8 against the restart
#: path at 1e-10): the restart path 1.65e-5 of a range either way; at rtol 1e-6 over the day the
#: restart path moves by 7e-6 of a range. The Python path (``TRACKINGBOX_NATIVE=0``) cannot.
KEEP_JACOBIAN = True



class Twin:
    """One FMU run that can be restarted from saved states or a replayed trajectory."""

    def __init__(self, path: Path, *, label: str, base: Mapping[str, float], inputs: pd.DataFrame | None,
                 tolerance: float, recorded: Mapping[str, str],
                 extrapolate: Mapping[str, tuple[float, float]] | None = None,
                 rename: Mapping[str, str] | None = None) -> None:
        self.label = label
        #: value name -> the FMU's variable that takes it (the tracked parameters' inputs of an inputs twin,
        #: :func:`~trackingbox.generate.inputs_twin.inputs_twin`); names not in it are the FMU's own
        self.rename = dict(rename or {})
        #: parameter -> bounds: applied over [t_k, t_k+1] as the mean of the controller's ramp over
        #: that sample, predicted from the last one (see :meth:`_applied`)
        self.extrapolate = dict(extrapolate or {})
        #: the values given for the previous step (before extrapolation)
        self.given: dict[str, float] = {}
        #: value name -> CSV column holding what was applied (for a replay)
        self.recorded = dict(recorded)
        self.model = open_model(path, tolerance=tolerance)
        self.base = dict(base)
        self.inputs = inputs
        self.me = self.model.interface == "ModelExchange"
        self.stepper: Any = None
        self.applied: dict[str, float] = {}
        self.x: npt.NDArray[np.float64] | None = None  # last good continuous states
        self.x_time = math.nan
        self.step_seconds = 0.0
        #: value name -> the largest change the integrator carries (no restart); empty: restart on every change
        self.carry_limits: dict[str, float] = {}
        #: restart the integrator at the next change whatever its size (set after a hold, a recovery)
        self.force_restart = False
        #: changes that re-initialised the integrator / that it carried, over all runs of this twin
        self.restarts = 0
        self.carried = 0
        #: the variables the loop reads after every step (read with the step, :meth:`get`), and their values
        self.read_names: list[str] | None = None
        self.y: npt.NDArray[np.float64] | None = None
        self._read_key: tuple[str, ...] = ()
        #: the solver's maximum step (None: the input table's smallest interval); a windowed run gives
        #: the whole grid's, which its input table, one window of it, may not show
        self.max_step: float | None = None
        #: rows -> an input table from the first row past row *rows* (a windowed run's replay from 0),
        #: None: :attr:`inputs` covers the run
        self.replay_inputs: Callable[[int], pd.DataFrame] | None = None

    def start(self, t: float, values: Mapping[str, float], x: Sequence[float] | None = None) -> None:
        """(Re)initialise at *t* with *values* applied; overwrite the states with *x* if given."""
        self._count()
        self.y = None
        self.stepper = self.model.stepper(start_time=t, parameters=self.fmu_values({**self.base, **values}),
                                          inputs=self.inputs, max_step=self.max_step,
                                          carry=bool(self.carry_limits) and self.me, keep_jacobian=KEEP_JACOBIAN)
        self.applied = dict(values)
        if x is not None:
            self.stepper.set_continuous_states(np.asarray(x, dtype=float))
        self._save()

    def _count(self) -> None:
        """Add the finished stepper's restarts and carried changes to the twin's counts."""
        st = self.stepper
        if st is not None and hasattr(st, "carried"):
            self.restarts += st.restarts
            self.carried += st.carried
            st.restarts = st.carried = 0

    def counts(self) -> tuple[int, int]:
        """``(restarts, carried)``: changes that re-initialised the integrator and changes it carried."""
        self._count()
        return self.restarts, self.carried

    def _small(self, changed: Mapping[str, float]) -> bool:
        """True if every change is within its carry limit (and none is forced to restart)."""
        limits = self.carry_limits
        if self.force_restart or not limits:
            return False
        applied = self.applied
        for name, value in changed.items():
            limit = limits.get(name)
            old = applied.get(name)
            if limit is None or old is None or not abs(value - old) <= limit:
                return False
        return True

    def fmu_name(self, name: str) -> str:
        """The FMU variable that takes the value *name* (see :attr:`rename`)."""
        return self.rename.get(name, name)

    def fmu_values(self, values: Mapping[str, float]) -> dict[str, float]:
        """*values* under the FMU's names (see :attr:`rename`)."""
        if not self.rename:
            return dict(values)
        return {self.rename.get(n, n): v for n, v in values.items()}

    def _save(self) -> None:
        if self.me:
            self.x = self.stepper.get_continuous_states()
            self.x_time = float(self.stepper.time)

    def get(self, names: Sequence[str]) -> npt.NDArray[np.float64]:
        """Current values of *names* (those of :attr:`read_names` as read with the last step)."""
        if names is self.read_names and self.y is not None:
            return self.y.copy()
        return self.stepper.get(names)

    def _applied(self, values: Mapping[str, float]) -> dict[str, float]:
        """The values to apply over the coming sample (:meth:`step` then remembers the given ones).

        A parameter in :attr:`extrapolate` with the controller's value ``p_k``
        at ``t_k`` (linear error interpolation) is applied as
        ``p_k + (p_k - p_k-1)/2``, clamped to its bounds: the compiled box's
        parameter ramps over the sample, and this is the ramp's mean predicted
        from the previous sample, so the twin does not see the parameter one
        half sample late.
        """
        out = dict(values)
        given = self.given
        for name, (lo, hi) in self.extrapolate.items():
            if name in values and name in given:
                p = float(values[name])
                x = p + 0.5 * (p - given[name])
                out[name] = lo if x < lo else hi if x > hi else x  # min(max(x, lo), hi), NaN kept
        return out

    def step(self, t_next: float, values: Mapping[str, float], code: int | None = None) -> None:
        """Apply the values that changed and integrate to *t_next*.

        *code*: the native stepper's ``tbn_advance`` for this step already ran
        (in a batch of rows, :class:`NativeRows`) and returned *code*; finish it.
        """
        given = {n: float(v) for n, v in values.items()}
        if self.extrapolate:
            values = self._applied(values)
        applied = self.applied
        changed = {n: v for n, v in values.items() if applied.get(n) != v}
        t0 = _time.perf_counter()
        stepper = self.stepper
        self.y = None
        if changed and self.force_restart and code is None and hasattr(stepper, "forget_jacobian"):
            stepper.forget_jacobian()  # a large change (start-up hold's end, a hold, a recovery): a new Jacobian
        if code is not None or (self.read_names is not None and isinstance(stepper, NativeStepper)):
            # the native stepper sets, steps and reads the states and the read variables in one C call
            fchanged = self.fmu_values(changed) if self.rename else changed
            try:
                if code is not None:
                    x, y = stepper.finish_advance(code, fchanged, t_next, self._read_key)
                else:
                    x, y = stepper.advance(fchanged, t_next, self._read_key,
                                           restart=not changed or not self._small(changed))
            except BaseException:
                if changed and stepper.holds(fchanged):  # the set went through, the step failed
                    self.force_restart = False
                    applied.update(changed)
                raise
            if changed:
                self.force_restart = False
                applied.update(changed)
            self.step_seconds += _time.perf_counter() - t0
            self.given = given
            self.x, self.x_time, self.y = x, float(stepper.time), y
            return
        if changed:
            stepper.set(self.fmu_values(changed), restart=not self._small(changed))
            self.force_restart = False
            applied.update(changed)
        stepper.step(t_next)
        self.step_seconds += _time.perf_counter() - t0
        self.given = given
        if self.me:  # _save
            self.x = stepper.get_continuous_states()
            self.x_time = float(stepper.time)

    def replay(self, t0: float, rows: Iterator[tuple[float, dict[str, float]]]) -> None:
        """Rebuild the run from *t0* by re-applying recorded values: ``(t_next, values)`` per step."""
        first = True
        self.given = {}
        forced, self.force_restart = self.force_restart, False
        for t_next, values in rows:
            if first:
                self.start(t0, values)
                first = False
            self.step(t_next, values)
        if first:
            self.start(t0, {})
        self.force_restart = forced

    def replay_csv(self, csv_path: Path, rows: int, grid: npt.NDArray[np.float64]) -> None:
        """Rebuild the run from 0 by replaying the values recorded in the first *rows* rows of the CSV."""
        if self.replay_inputs is None:
            self.replay(0.0, read_rows(csv_path, rows, self.recorded, grid))
            return
        current = self.inputs
        self.inputs = self.replay_inputs(rows)  # from row 0: the one place a windowed run holds that much
        try:
            self.replay(0.0, read_rows(csv_path, rows, self.recorded, grid))
        finally:
            self.inputs = current
        self.stepper.replace_inputs(current)

    def state_dict(self) -> dict[str, Any]:
        """The values applied and, for model exchange, the continuous states after the last step."""
        return {"applied": dict(self.applied), "given": dict(self.given),
                "x": self.x.tolist() if self.x is not None else None, "force_restart": self.force_restart,
                "counts": list(self.counts())}

    def load_state_dict(self, state: Mapping[str, Any], *, t: float, csv_path: Path, rows: int,
                        grid: npt.NDArray[np.float64], substeps: int = 1) -> None:
        """Put the twin at *t* as :meth:`state_dict` saved it: from its states, else by replaying the CSV."""
        x = state.get("x")
        self.force_restart = bool(state.get("force_restart", False))
        counts = [int(c) for c in state.get("counts", (0, 0))]
        if x is None and substeps > 1:
            log.warning("%s twin: no states in the checkpoint; the replay applies the recorded values once "
                        "a sample, not the %d sub-steps of each, so the resumed run is close to, not "
                        "identical with, an uninterrupted one", self.label, substeps)
        if x is not None and self.me:
            self.start(t, {n: float(v) for n, v in state["applied"].items()}, x)
            self.given = {n: float(v) for n, v in state.get("given", {}).items()}
        else:
            self.replay_csv(csv_path, rows, grid)
        self._count()  # the replay's own changes are not the run's
        self.restarts, self.carried = counts

    def close(self) -> None:
        self.model.close()
