"""The native model-exchange stepper: :class:`NativeStepper`, integration in C.

A :class:`~trackingbox.fmu.steppers.ModelExchangeStepper` (same public API, counters and error
texts) whose steps run in the C library of :mod:`trackingbox.native` (CVODE and the FMU's
right-hand side, no Python inside a step). :meth:`FMUModel.stepper
<trackingbox.fmu.model.FMUModel.stepper>` makes it for an event-free FMI 3 model-exchange FMU
(:func:`trackingbox.native.native_reason`). The library knows nothing of this package: the
dependency runs one way, from here to :mod:`trackingbox.native`.
"""
from __future__ import annotations

import ctypes
import math
import weakref
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt
import pandas as pd
from fmpy.fmi1 import FMICallException
from fmpy.sundials import libraries as sl

from ..errors import FMUError, SimulationError
from ..native import (
    AFTER_SET,
    CARRY,
    CVODE_FAILED,
    EVENT,
    EXACT,
    FMU_FAILED,
    NONFINITE,
    OK,
    PD,
    READ_FAILED,
    STEP_EVENT,
    TERMINATE,
    library,
)
from .calls import fmu_calls, simulation_failure
from .steppers import ModelExchangeStepper

if TYPE_CHECKING:
    from .adapters import FMIAdapter
    from .model import FMUModel


class _Solver:
    """What :class:`~trackingbox.fmu.ModelExchangeStepper` asks of its solver, on the native CVODE."""

    def __init__(self, lib: ctypes.CDLL, handle: int) -> None:
        self.lib = lib
        self.handle = handle
        #: stop exactly at each target time (carry mode)
        self.exact = False

    def reset(self, time: float) -> None:
        code = self.lib.tbn_reset(self.handle, time)
        if code != OK:
            raise RuntimeError(f"re-initialising CVODE at t = {time:g} s failed "
                               f"({_failure_text(self.lib, self.handle)})")

    def internal_time(self) -> float:
        return float(self.lib.tbn_internal_time(self.handle))


def _failure_text(lib: ctypes.CDLL, handle: int) -> str:
    status = ctypes.c_int(0)
    call = lib.tbn_failed_call(handle, ctypes.byref(status))
    if call:
        return str(_fmi_exception(call.decode(), status.value))
    return (lib.tbn_error(handle) or b"").decode("utf-8", "replace").strip()


def _fmi_exception(function: str, status: int) -> Exception:
    """The exception fmpy raises for a failed FMI call (the Python path's cause, word for word)."""
    return FMICallException(function=function, status=status)


class _SetPlan(NamedTuple):
    """How :meth:`NativeStepper.set` writes one tuple of names in C."""

    n: int
    vr: Any  # ctypes uint32 array of the value references
    buffer: npt.NDArray[np.float64]
    pointer: Any  # the buffer's data pointer
    parameters: tuple[str, ...]  # the tunable parameters among the names (event mode when any)
    inputs: frozenset[str]


class NativeStepper(ModelExchangeStepper):
    """A :class:`~trackingbox.fmu.ModelExchangeStepper` whose integration runs in C (see the module docstring).

    Made by :meth:`FMUModel.stepper <trackingbox.fmu.FMUModel.stepper>` for an
    event-free FMI 3 model-exchange FMU (``native=None`` or ``True``); never
    constructed directly. Everything but :meth:`step`'s inside is inherited:
    :meth:`set` (event mode through fmpy, carried or restarted), ``get``,
    ``reader``, the continuous-state access, ``restarts``/``carried``, and the
    error texts, which name the same calls and times as the Python path.
    """

    def __init__(self, model: FMUModel, fmi: FMIAdapter, *, start_time: float, parameters: dict[str, Any],
                 inputs: pd.DataFrame | None, max_step: float | None) -> None:
        self._lib = library()
        self._handle: int | None = None
        #: the input table's arrays C reads in place (kept referenced here)
        self._c_inputs: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None
        self._reached = ctypes.c_double(0.0)
        self._reached_ref = ctypes.byref(self._reached)
        self._free: weakref.finalize | None = None
        #: names of a set() -> how to write them in C (None: not all tunable Real parameters, the generic path)
        self._plans: dict[tuple[str, ...], _SetPlan | None] = {}
        self._next_defined = ctypes.c_int(0)
        self._next_time = ctypes.c_double(0.0)
        self._next_defined_ref = ctypes.byref(self._next_defined)
        self._next_time_ref = ctypes.byref(self._next_time)
        self._set_code = ctypes.c_int(0)
        self._set_code_ref = ctypes.byref(self._set_code)
        #: names read by advance() -> (count, buffer, value references, buffer pointer), None: not all Real
        self._read_plans: dict[tuple[str, ...], tuple[int, npt.NDArray[np.float64], Any, Any] | None] = {}
        self._reads_set: Any = None  # the read plan C has (tbn_advance_reads)
        #: advance()'s last *read* argument, its names and read plan
        self._last_read: tuple[Any, Any, Any] = (None, None, None)
        #: closed-loop integrators (:meth:`closed`): key -> (handle, the arrays C keeps, finaliser)
        self._closed: dict[tuple[Any, ...], tuple[Any, ...]] = {}
        super().__init__(model, fmi, start_time=start_time, parameters=parameters, inputs=inputs,
                         max_step=max_step)

    def _start(self, max_step: float | None) -> None:
        if max_step is None:
            max_step = float("inf")
            if self._in_times is not None and self._in_times.size > 1:
                max_step = float(np.min(np.diff(self._in_times)))
        libs = (ctypes.c_void_p * 5)(*(lib._handle for lib in (
            sl.sundials_core, sl.sundials_nvecserial, sl.sundials_sunmatrixdense, sl.sundials_sunlinsoldense,
            sl.sundials_cvode)))
        fmu = self._fmu
        err = ctypes.create_string_buffer(512)
        handle = self._lib.tbn_new(libs, fmu.dll._handle, fmu.component, self._nx, self.time,
                                   self.model.tolerance, max_step, 100000,
                                   int(self._fmi.needs_completed_integrator_step()), err, len(err))
        if not handle:
            raise FMUError(f"the native stepper could not start on {self.model.path.name}: "
                           f"{err.value.decode('utf-8', 'replace')}")
        self._handle = handle
        self._free = weakref.finalize(self, self._lib.tbn_free, handle)
        self._solver = _Solver(self._lib, handle)
        self._push_inputs()
        self._step_c = self._lib.tbn_step
        self._check_states()

    # -- the input table lives in C too ------------------------------------------------
    def _push_inputs(self) -> None:
        if self._handle is None:
            return
        if self._in_set is None or self._in_times is None or self._in_table is None:
            self._lib.tbn_set_inputs(self._handle, 0, None, 0, None, None)
            self._c_inputs = None
            return
        vrs = [int(self.model.variable(n).valueReference) for n in self._in_names]
        vr = (ctypes.c_uint32 * len(vrs))(*vrs)
        t = np.ascontiguousarray(self._in_times, dtype=float)
        u = np.ascontiguousarray(self._in_table, dtype=float)
        dp = ctypes.POINTER(ctypes.c_double)
        if self._lib.tbn_set_inputs(self._handle, len(vrs), vr, t.size, t.ctypes.data_as(dp),
                                    u.ctypes.data_as(dp)) != 0:
            raise MemoryError(f"no memory for the input table of {self.model.path.name}")
        # C reads these arrays in place (no copy): they live as long as C may read them
        self._c_inputs = (t, u)

    def _drop_inputs(self, names: set[str]) -> None:
        before = list(self._in_names)
        super()._drop_inputs(names)
        if self._in_names != before:
            self._push_inputs()

    def replace_inputs(self, inputs: pd.DataFrame) -> None:
        super().replace_inputs(inputs)
        self._push_inputs()

    def closed(self, n_pairs: int, set_names: Sequence[str], sim_names: Sequence[str],
               nominal: Sequence[float]) -> int:
        """The closed-loop integrator of this twin for ``tbn_closed_rows`` (made once per stepper and names).

        *set_names*: the Real inputs the loop drives (*n_pairs* parameters, then
        the corrections); *sim_names*: the variable each of them reads;
        *nominal*: the nominal values of the controllers' ``2 len(set_names)``
        states (absolute tolerance ``rtol * nominal``, as for the FMU's states).
        """
        key = (n_pairs, tuple(set_names), tuple(sim_names), tuple(nominal))
        got = self._closed.get(key)
        if got is not None:
            return got[0]
        for name in set_names:
            v = self.model.variable(name)
            if v.causality != "input" or v.type not in ("Real", "Float64"):
                raise FMUError(f"{name!r} of {self.model.path.name} is not a Real input (causality "
                               f"{v.causality!r}): the closed loop sets it inside the right-hand side")
        n = len(set_names)
        vr_set = (ctypes.c_uint32 * max(n, 1))(*(int(self.model.variable(x).valueReference) for x in set_names))
        vr_sim = (ctypes.c_uint32 * max(n, 1))(*(int(self.model.variable(x).valueReference) for x in sim_names))
        nom = np.ascontiguousarray(nominal, dtype=float)
        err = ctypes.create_string_buffer(512)
        max_step = self.max_step_given if self.max_step_given is not None else float("inf")
        if self.max_step_given is None and self._in_times is not None and self._in_times.size > 1:
            max_step = float(np.min(np.diff(self._in_times)))
        handle = self._lib.tbn_closed_new(self._handle, n_pairs, n - n_pairs, vr_set, vr_sim,
                                          nom.ctypes.data_as(PD), max_step, 100000, err, len(err))
        if not handle:
            raise FMUError(f"the closed-loop integrator could not start on {self.model.path.name}: "
                           f"{err.value.decode('utf-8', 'replace')}")
        self._closed[key] = (handle, vr_set, vr_sim, nom, weakref.finalize(self, self._lib.tbn_closed_free, handle))
        return handle

    def finish(self) -> None:
        for got in self._closed.values():
            got[-1]()
        self._closed = {}
        super().finish()
        if self._free is not None:
            self._free()  # the CVODE instance goes now; the FMU instance stays with its model
        self._c_inputs = None

    # -- stepping -----------------------------------------------------------------------
    def _advance(self, t_next: float) -> None:
        while self.time < t_next - 1e-12 * max(1.0, abs(t_next)):
            target = t_next
            if self._next_event is not None and self.time < self._next_event < t_next:
                target = self._next_event
            code = self._step_c(self._handle, target, 1 if self._solver.exact else 0, self._reached_ref)
            self._after_step(code, target)
        self.time = t_next

    def _after_step(self, code: int, target: float) -> None:
        """What the Python path does after a solver step towards *target*, from tbn_step's *code*."""
        name = self.model.path.name
        if code == CVODE_FAILED:
            raise simulation_failure(f"solver failed in {name} between t = {self.time:g} s and "
                                      f"t = {target:g} s", _failure_text(self._lib, self._handle),
                                      self.model.log_messages, solver=True) from None
        self.time = float(self._reached.value)
        if code == FMU_FAILED:
            raise simulation_failure(f"simulation of {name} failed at t = {self.time:g} s",
                                      _failure_text(self._lib, self._handle), self.model.log_messages)
        if code == TERMINATE:
            raise SimulationError(f"{name} requested termination at t = {self.time:g} s")
        time_event = self._next_event is not None and math.isclose(self.time, self._next_event)
        if code == STEP_EVENT or time_event:
            with fmu_calls(f"simulation of {name} failed at t = {self.time:g} s", self.model.log_messages):
                self._event_iteration()
                self._solver.reset(self.time)
            self._check_states()
        elif code == NONFINITE:
            self._check_states()  # raises, with the Python path's text

    # -- parameters and states between steps ---------------------------------------------
    def _plan(self, names: tuple[str, ...]) -> _SetPlan | None:
        params, inputs, vrs = [], [], []
        for name in names:
            v = self.model.variable(name)
            if v.type not in ("Real", "Float64"):
                return None
            if v.causality == "parameter" and v.variability == "tunable":
                params.append(name)
            elif v.causality == "input":
                inputs.append(name)
            else:
                return None  # the Python path raises its error
            vrs.append(int(v.valueReference))
        buf = np.zeros(len(vrs))
        return _SetPlan(len(vrs), (ctypes.c_uint32 * len(vrs))(*vrs), buf,
                        buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), tuple(params), frozenset(inputs))

    def _set_plan(self, values: Mapping[str, float]) -> tuple[dict[str, Any], _SetPlan | None] | None:
        """The changed values of a :meth:`set` and how C writes them (plan None: the Python path); None: no change."""
        last = self._last_set
        changed = {n: v for n, v in values.items() if last.get(n) != v}
        if not changed:
            return None
        key = tuple(changed)
        try:
            plan = self._plans[key]
        except KeyError:
            plan = self._plans[key] = self._plan(key)
        if plan is not None and str in map(type, changed.values()):
            plan = None
        return changed, plan

    def _load_plan(self, changed: dict[str, Any], plan: _SetPlan) -> None:
        """Before the C call of a set: drop table inputs that are set explicitly, fill the plan's buffer."""
        if plan.inputs and self._in_names:
            self._drop_inputs(set(plan.inputs))  # an input set here is no longer driven by the table
        plan.buffer[:] = list(changed.values())

    def _after_set(self, code: int, changed: dict[str, Any], plan: _SetPlan) -> None:
        """After the C call of a set with tbn_set_parameters's *code*: errors, next time event, counters."""
        if code < 0:
            name = self.model.path.name
            raise simulation_failure(f"setting {', '.join(changed)} in {name} at t = {self.time:g} s failed",
                                      _failure_text(self._lib, self._handle), self.model.log_messages)
        if code == TERMINATE:
            raise SimulationError(f"{self.model.path.name} requested termination at t = {self.time:g} s")
        if self._next_defined.value >= 0:
            self._next_event = float(self._next_time.value) if self._next_defined.value else None
        if code == 1:
            self.carried += 1
        else:
            self.restarts += 1
        if plan.parameters:
            self.model.note_changed(plan.parameters)
        self._last_set.update(changed)

    def set(self, values: Mapping[str, float], *, restart: bool = True) -> None:
        """As :meth:`ModelExchangeStepper.set <trackingbox.fmu.Stepper.set>`, with Real values written in C.

        The sequence (event mode when a parameter changes, write, event
        iteration, continuous-time mode, then carry or re-initialise) is the
        Python path's, call for call; other types take the Python path itself.
        """
        if self._finished:
            self._check_open()
        planned = self._set_plan(values)
        if planned is None:
            return
        changed, plan = planned
        if plan is None:
            super().set(values, restart=restart)
            return
        self._load_plan(changed, plan)
        carry = not restart and self._solver.exact
        code = self._lib.tbn_set_parameters(self._handle, plan.n, plan.vr, plan.pointer, 1 if plan.parameters else 0,
                                            1 if carry else 0, self.time, self._next_defined, self._next_time)
        self._after_set(code, changed, plan)

    def holds(self, values: Mapping[str, float]) -> bool:
        """True if *values* are what :meth:`set` last wrote (a set of them would change nothing)."""
        last = self._last_set
        return all(n in last and last[n] == v for n, v in values.items())

    def _read_plan(self, names: tuple[str, ...]) -> tuple[int, npt.NDArray[np.float64]] | None:
        """Make tbn_advance read *names* (all Real) into a buffer: ``(count, buffer)``; None: not all Real."""
        try:
            plan = self._read_plans[names]
        except KeyError:
            variables = [self.model.variable(n) for n in names]
            plan = None
            if all(v.type in ("Real", "Float64") for v in variables):
                n = len(variables)
                buf = np.zeros(max(n, 1))
                vr = (ctypes.c_uint32 * max(n, 1))(*(int(v.valueReference) for v in variables))
                plan = (n, buf, vr, buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
            self._read_plans[names] = plan
        if plan is None:
            return None
        if self._reads_set is not plan:
            # C keeps these pointers: the plan's arrays live in self._read_plans as long as this stepper
            self._lib.tbn_advance_reads(self._handle, plan[0], plan[2], plan[3], self._px, self._set_code_ref,
                                        self._next_defined_ref, self._next_time_ref, self._reached_ref)
            self._reads_set = plan
        return plan[0], plan[1]

    def advance(self, values: Mapping[str, float], t_next: float, read: Sequence[str], *,
                restart: bool = True) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """``set(values, restart=restart)``, ``step(t_next)``, then the states and *read*: in one C call.

        Returns ``(get_continuous_states(), get(read))``. The same FMU and
        CVODE calls in the same order as those methods one after the other
        (``tbn_advance``), with the same results and errors; where a part
        needs Python (a time event, a value that is not a Real, a step event,
        a failure) it is finished, or raised, by those methods themselves.
        """
        if self._finished:
            self._check_open()
        t_next = float(t_next)
        if read is self._last_read[0]:  # the same tuple as last time: the same plan
            names, rplan = self._last_read[1], self._last_read[2]
            if rplan is not None and self._reads_set is not self._read_plans[names]:
                rplan = self._read_plan(names)
        else:
            names = tuple(read)
            rplan = self._read_plan(names)
            self._last_read = (read, names, rplan) if type(read) is tuple else (None, None, None)
        planned = self._set_plan(values) if values else None
        if rplan is None or self._next_event is not None or t_next <= self.time + 1e-12 * max(1.0, abs(t_next)) \
                or (planned is not None and planned[1] is None):
            self.set(values, restart=restart)
            self.step(t_next)
            return self.get_continuous_states(), self.get(names)
        exact = self._solver.exact
        if planned is None:
            code = self._lib.tbn_advance(self._handle, 0, None, None, EXACT if exact else 0, self.time, t_next)
        else:
            changed, plan = planned
            if plan.inputs and self._in_names:
                self._drop_inputs(set(plan.inputs))  # an input set here is no longer driven by the table
            plan.buffer[:] = list(changed.values())
            flags = (EVENT if plan.parameters else 0) | (CARRY if exact and not restart else 0) | \
                (EXACT if exact else 0)
            code = self._lib.tbn_advance(self._handle, plan.n, plan.vr, plan.pointer, flags, self.time, t_next)
        return self._advance_end(code, planned, t_next, names, rplan)

    def _advance_end(self, code: int, planned: tuple[dict[str, Any], Any] | None, t_next: float,
                     names: tuple[str, ...], rplan: tuple[int, npt.NDArray[np.float64]]
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """What :meth:`advance` does after its ``tbn_advance`` call returned *code*."""
        if planned is not None:
            self._after_set(self._set_code.value, *planned)  # raises when the set failed
        if code == OK:
            self.time = t_next
            return self._x[: self._nx].copy(), rplan[1][: rplan[0]].copy()
        if code == READ_FAILED:
            self.time = t_next
            status = ctypes.c_int(0)
            call = self._lib.tbn_failed_call(self._handle, ctypes.byref(status))
            raise _fmi_exception(call.decode(), status.value)
        if code == AFTER_SET:
            self.step(t_next)
        else:
            # the step did not end normally: what step() does after tbn_step's code
            self._after_step(code, t_next)
            self._advance(t_next)
            self.time = t_next
        return self.get_continuous_states(), self.get(names)

    # -- batches of tracking rows (tbn_track_rows, TrackingLoop's fast path) ---------------------
    def rows_ready(self, names: Sequence[str], read: Sequence[str]) -> tuple[npt.NDArray[np.float64], list[int],
                                                                             list[int]] | None:
        """Ready for ``tbn_track_rows`` to advance this stepper with *names* set and *read* read, or None.

        Returns the buffer ``tbn_advance`` reads *read* into, the value
        references of *names* and whether each is a parameter (event mode).
        None where the batch cannot do what :meth:`advance` would: a time
        event ahead, a read or a value that is not a Real tunable parameter or
        input, an input still driven by the table.
        """
        if self._finished or self._next_event is not None:
            return None
        rplan = self._read_plan(tuple(read))
        if rplan is None:
            return None
        key = tuple(names)
        if key:
            plan = self._plans.get(key)
            if plan is None:
                plan = self._plans[key] = self._plan(key)
            if plan is None or (plan.inputs and set(plan.inputs) & set(self._in_names)):
                return None
        params = set(self._plans[key].parameters) if key else set()
        vrs = [int(self.model.variable(n).valueReference) for n in key]
        return self._read_plans[tuple(read)][1], vrs, [1 if n in params else 0 for n in key]

    def rows_done(self, time: float, carried: int, restarts: int, set_values: Mapping[str, float]) -> None:
        """After ``tbn_track_rows``: its time, the outcomes of its sets and the values it set last."""
        self.time = float(time)
        self.carried += int(carried)
        self.restarts += int(restarts)
        if set_values:
            self._last_set.update(set_values)
            self.model.note_changed(n for n in set_values
                                    if self.model.variable(n).causality == "parameter")

    def finish_advance(self, code: int, values: Mapping[str, float], t_next: float, read: Sequence[str]
                       ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """End an :meth:`advance` of *values* to *t_next* whose ``tbn_advance`` (in ``tbn_track_rows``) returned *code*.

        What :meth:`advance` does after its C call: the set's outcome (or its
        error), then the step's (a step event, a failure), the reads.
        """
        names = tuple(read)
        rplan = self._read_plan(names)
        assert rplan is not None
        planned = self._set_plan(values) if values else None
        return self._advance_end(int(code), planned, float(t_next), names, rplan)

    def get_continuous_states(self) -> npt.NDArray[np.float64]:
        """The continuous state vector, for checkpoints (one C call)."""
        if self._finished:
            self._check_open()
        if self._lib.tbn_get_states(self._handle, self._px) != OK:
            status = ctypes.c_int(0)
            call = self._lib.tbn_failed_call(self._handle, ctypes.byref(status))
            raise _fmi_exception(call.decode(), status.value)
        return self._x[: self._nx].copy()

    def _getter(self, names: tuple[str, ...]) -> Callable[[], npt.NDArray[np.float64]]:
        """As the Python path's, with Real reads calling the FMU's ``fmi3GetFloat64`` directly.

        fmpy's wrapper of that call adds a Python frame and a status check per
        read; this checks the status itself and raises fmpy's exception.
        """
        getter = self._getters.get(names)
        if getter is not None:
            return getter
        variables = [self.model.variable(n) for n in names]
        if not all(v.type in ("Real", "Float64") for v in variables):
            return super()._getter(names)
        n = len(variables)
        vr = (ctypes.c_uint32 * n)(*(int(v.valueReference) for v in variables))
        buf = np.zeros(n)
        pbuf = buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        func = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint32), ctypes.c_size_t,
                                ctypes.POINTER(ctypes.c_double), ctypes.c_size_t)(
            ctypes.cast(self._fmu.dll.fmi3GetFloat64, ctypes.c_void_p).value)
        comp = ctypes.c_void_p(self._fmu.component)

        def getter() -> npt.NDArray[np.float64]:
            status = func(comp, vr, n, pbuf, n)
            if status > 1:
                raise _fmi_exception("fmi3GetFloat64", status)
            return buf.copy()

        self._getters[names] = getter
        return getter

    def step(self, t_next: float) -> None:
        """Integrate from :attr:`time` to *t_next* (as :meth:`Stepper.step <trackingbox.fmu.Stepper.step>`)."""
        if self._finished:
            self._check_open()
        t_next = float(t_next)
        if t_next <= self.time + 1e-12 * max(1.0, abs(t_next)):
            super().step(t_next)  # nothing to do, or the error for a step back in time
        elif self._next_event is None:
            # one solver call reaches t_next (CV_NORMAL, no time event before it): _advance's loop, once
            code = self._step_c(self._handle, t_next, 1 if self._solver.exact else 0, self._reached_ref)
            if code != OK:
                self._after_step(code, t_next)
                self._advance(t_next)
            self.time = t_next
        else:
            self._advance(t_next)

    def keep_jacobian(self, on: bool = True) -> None:
        """Reuse CVODE's last Jacobian for the first step after a change that re-initialises it (*on*).

        ``CVodeReInit`` makes CVODE evaluate a new difference-quotient Jacobian
        (one right-hand side per state) at its first step. After a small change
        of parameters or inputs the last one is still a good Newton matrix: the
        Jacobian only steers the Newton iteration, not the error test, and when
        the iteration fails to converge CVODE asks again and gets a fresh one.
        Every other evaluation is CVODE's own difference quotient
        (``cvLsDQJac``, called as CVODE calls it: the same values). Restarts of
        :meth:`set` (and :meth:`advance`) only; a new stepper starts with none,
        and :meth:`forget_jacobian` drops it before a large change.
        On the tracking loop's restart path (heat production, one day) this
        halves the right-hand-side evaluations; the trajectory moves within the
        solver's tolerance (the Newton iterates change), so it is not the
        Python path's bit for bit.
        """
        self._check_open()
        if self._lib.tbn_keep_jacobian(self._handle, 1 if on else 0) != 0:
            raise FMUError(f"the native stepper on {self.model.path.name} could not keep its Jacobian "
                           "(out of memory, or CVODE refused its Jacobian function)")

    def forget_jacobian(self) -> None:
        """The next restart evaluates a new Jacobian (:meth:`keep_jacobian`): before a large change."""
        self._check_open()
        self._lib.tbn_forget_jacobian(self._handle)

    def jacobians(self) -> tuple[int, int]:
        """``(reused, computed)``: Jacobians kept across a restart (:meth:`keep_jacobian`) and evaluated since it."""
        self._check_open()
        reused, computed = ctypes.c_long(0), ctypes.c_long(0)
        self._lib.tbn_jacobians(self._handle, ctypes.byref(reused), ctypes.byref(computed))
        return int(reused.value), int(computed.value)

    def solver_statistics(self) -> Mapping[str, int]:
        """CVODE's counters since the last (re-)initialisation: ``steps`` and ``rhs`` evaluations."""
        self._check_open()
        steps, rhs = ctypes.c_long(0), ctypes.c_long(0)
        self._lib.tbn_stats(self._handle, ctypes.byref(steps), ctypes.byref(rhs))
        return {"steps": int(steps.value), "rhs": int(rhs.value)}
