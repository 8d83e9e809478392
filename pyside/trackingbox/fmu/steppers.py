"""Advance an FMU one communication step at a time: :class:`Stepper` and its drivers.

:class:`ModelExchangeStepper` integrates with CVODE (BDF, dense direct solver) from fmpy's
bundled SUNDIALS; after every parameter change, input override or state overwrite the
integrator is re-initialised (or carries a small change, :meth:`ModelExchangeStepper.carry`).
:class:`CoSimulationStepper` advances with ``doStep``.
"""
from __future__ import annotations

import abc
import ctypes
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from fmpy.model_description import ModelVariable
from fmpy.sundials import CVodeSolver
from fmpy.sundials.cvode import CV_NORMAL, CVode, CVodeGetRootInfo, sundials_cvode
from fmpy.sundials.sundials_types import sunrealtype

from ..errors import DataError, FMUError, SimulationError, unknown_name
from .adapters import FMIAdapter
from .calls import fmu_calls, simulation_failure
from .info import REAL_TYPES, change_refusal
from .steady import free_states, no_steady_state, settle_by_integration, spread

if TYPE_CHECKING:
    from .model import FMUModel

log = logging.getLogger(__name__)

#: How measured inputs reach an FMU between their samples (the spec's ``[data] inputs``):
#: ``"linear"`` interpolated between samples, ``"hold"`` held at the last sample until the next.
INPUT_RULES = ("linear", "hold")
#: Co-simulation under the ``"linear"`` rule when the FMU cannot interpolate inputs itself (no input
#: derivatives: FMI 2 without ``canInterpolateInputs``, every FMI 3 FMU): each step between two input
#: samples is split into this many sub-steps, each with the input at its midpoint (the ramp's mean
#: over the sub-step); the difference from an exact ramp falls with the square of the sub-step.
CS_LINEAR_SUBSTEPS = 8

# ---------------------------------------------------------------------------
# Stepper: the interface, and one driver per FMI interface
# ---------------------------------------------------------------------------

class Stepper(abc.ABC):
    """One run of an FMU, advanced communication step by communication step.

    Create with :meth:`FMUModel.stepper`, which returns the driver for the
    model's interface (:class:`ModelExchangeStepper` or
    :class:`CoSimulationStepper`). Between steps, :meth:`set` changes tunable
    parameters and inputs and :meth:`get` reads any variables.

    Attributes
    ----------
    time : float
        The current simulation time (s).
    """

    def __init__(self, model: FMUModel, fmi: FMIAdapter, *, start_time: float, parameters: dict[str, Any],
                 inputs: pd.DataFrame | None, max_step: float | None, input_rule: str = "linear") -> None:
        if input_rule not in INPUT_RULES:
            raise FMUError(f"input rule must be one of {', '.join(INPUT_RULES)}, not {input_rule!r}")
        #: how the ``inputs`` table reaches the FMU between its samples (:data:`INPUT_RULES`)
        self.input_rule = input_rule
        self._held = input_rule == "hold"
        self.model = model
        self.time = start_time
        self._finished = False
        self._fmi = fmi
        self._fmu = fmi.instance
        self._getters: dict[tuple[str, ...], Callable[[], npt.NDArray[np.float64]]] = {}
        self._setters: dict[tuple[str, ...], Callable[[Any], None]] = {}
        self._in_names: list[str] = []
        self._in_times: npt.NDArray[np.float64] | None = None
        self._in_table: npt.NDArray[np.float64] | None = None
        self._in_set: Callable[[Any], None] | None = None
        self._in_i, self._in_t0, self._in_t1 = 1, math.inf, -math.inf  # the interval _input_values used last
        self._last_set: dict[str, Any] = {}
        #: every value given before initialisation or set since: what a re-initialisation sets again
        self._given: dict[str, Any] = {}
        #: the maximum step given (None: the input table's smallest interval)
        self.max_step_given = max_step
        self._prepare_inputs(inputs)
        self._initialize(parameters, max_step)

    # -- what each driver provides ------------------------------------------------
    def _after_initialization(self) -> None:
        """Called inside initialisation, after ``exitInitializationMode``."""

    def _start(self, max_step: float | None) -> None:
        """Called once initialisation succeeded."""

    @abc.abstractmethod
    def _advance(self, t_next: float) -> None:
        """Advance from :attr:`time` to *t_next* (> :attr:`time`)."""

    @abc.abstractmethod
    def _apply_set(self, values: Mapping[str, Any], parameters_changed: bool, restart: bool = True) -> None:
        """Write *values* between steps (inside the error translation of :meth:`set`)."""

    # -- inputs -------------------------------------------------------------
    def _prepare_inputs(self, inputs: pd.DataFrame | None) -> None:
        if inputs is None:
            return
        where = "the inputs table"
        if "time" not in inputs.columns:
            raise DataError(f"{where} has no 'time' column (columns: {', '.join(map(str, inputs.columns))})")
        names = [str(c) for c in inputs.columns if c != "time"]
        model_inputs = self.model.info.inputs
        for name in names:
            if name not in model_inputs:
                raise FMUError(unknown_name("input", name, model_inputs, f"FMU {self.model.path.name}"))
            kind = self.model.variable(name).type
            if kind not in REAL_TYPES:
                raise FMUError(f"input {name!r} of FMU {self.model.path.name} is {kind}; "
                               "only Real inputs can be driven from a table")
        try:
            t = inputs["time"].to_numpy(dtype=float)
            table = inputs[names].to_numpy(dtype=float) if names else np.zeros((len(t), 0))
        except (TypeError, ValueError) as exc:
            raise DataError(f"{where} has non-numeric values: {exc}") from None
        if t.size == 0:
            raise DataError(f"{where} has no rows")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise DataError(f"{where}: 'time' must be finite and strictly increasing")
        for j, name in enumerate(names):
            bad = ~np.isfinite(table[:, j])
            if bad.any():
                raise DataError(f"input {name!r} in {where} has {int(bad.sum())} NaN/inf values "
                                f"(first at t = {t[bad][0]:g} s)")
        if not names:
            return
        self._in_names = names
        self._in_times = t
        self._in_table = np.ascontiguousarray(table)
        self._in_set = self._setter(tuple(names))

    def extend_inputs(self, inputs: pd.DataFrame) -> None:
        """Go on with a longer table of the same inputs, whose first rows are the current table.

        For a run that receives its inputs as they come (the online mode). Only
        exact when the solver has not looked past the current table's end: a
        model-exchange stepper made with ``carry=True`` stops at every
        communication point, so it never has.
        """
        self.replace_inputs(inputs)

    def replace_inputs(self, inputs: pd.DataFrame) -> None:
        """Go on with another table of the same inputs (no restart).

        The run is the one the old table would have given when the new one holds
        the same rows over every time the solver still asks for: from the
        current time (its first row at or before it) to past the next stop,
        by more than one step of the solver (:mod:`trackingbox.stream`: a long
        run's input table, window by window). Inputs the run set explicitly
        stay off the table.
        """
        self._check_open()
        names = list(self._in_names)
        self._prepare_inputs(inputs)
        self._drop_inputs(set(self._in_names) - set(names))
        self._in_i, self._in_t0, self._in_t1 = 1, math.inf, -math.inf

    @property
    def input_times(self) -> npt.NDArray[np.float64] | None:
        """Sample times of the ``inputs`` table of this run (``None`` without one)."""
        return self._in_times

    def _input_values(self, t: float) -> npt.NDArray[np.float64]:
        times, table = self._in_times, self._in_table
        assert times is not None and table is not None
        if t <= times[0]:
            return table[0]
        if t >= times[-1]:
            return table[-1]
        # the solver asks for times close to the last one: try the last interval first (a
        # binary search per right-hand side evaluation was a third of a tracking run's cost)
        i = self._in_i
        t0, t1 = self._in_t0, self._in_t1
        if not t0 <= t < t1:
            i = int(np.searchsorted(times, t, side="right"))
            t0, t1 = times[i - 1], times[i]
            self._in_i, self._in_t0, self._in_t1 = i, t0, t1
        w = (t - t0) / (t1 - t0)
        return table[i - 1] + w * (table[i] - table[i - 1])

    def _held_values(self, t: float) -> npt.NDArray[np.float64]:
        """The table's row of the last sample at or before *t* (the first row before the table)."""
        times, table = self._in_times, self._in_table
        assert times is not None and table is not None
        i = int(np.searchsorted(times, t + 1e-12 * max(1.0, abs(t)), side="right")) - 1
        return table[max(i, 0)]

    def _rule_values(self, t: float) -> npt.NDArray[np.float64]:
        """The inputs at *t* under this run's rule (at a sample time both rules give the sample)."""
        return self._held_values(t) if self._held else self._input_values(t)

    def _apply_inputs(self, t: float) -> None:
        if self._in_set is not None:
            self._in_set(self._rule_values(t))

    def _input_breaks(self, t0: float, t1: float) -> list[float]:
        """Input sample times strictly between *t0* and *t1*, then *t1*: where a held input may jump."""
        times = self._in_times
        if times is None or self._in_set is None:
            return [t1]
        tol = 1e-12 * max(1.0, abs(t1))
        lo = int(np.searchsorted(times, t0 + tol, side="right"))
        hi = int(np.searchsorted(times, t1 - tol, side="left"))
        return [*(float(x) for x in times[lo:hi]), t1]

    def _drop_inputs(self, names: set[str]) -> None:
        """Stop driving *names* from the table (the caller set them explicitly)."""
        if not self._in_names or not names.intersection(self._in_names):
            return
        keep = [j for j, n in enumerate(self._in_names) if n not in names]
        assert self._in_table is not None
        self._in_names = [self._in_names[j] for j in keep]
        self._in_table = np.ascontiguousarray(self._in_table[:, keep])
        self._in_set = self._setter(tuple(self._in_names)) if self._in_names else None

    # -- value access -----------------------------------------------------------
    def _getter(self, names: tuple[str, ...]) -> Callable[[], npt.NDArray[np.float64]]:
        getter = self._getters.get(names)
        if getter is not None:
            return getter
        fmu = self._fmu
        variables = [self.model.variable(n) for n in names]
        if all(v.type in ("Real", "Float64") for v in variables):
            getter = self._fmi.real_reader([v.valueReference for v in variables])
        else:
            calls = []
            for v in variables:
                kind = v.type
                if kind == "Enumeration":
                    kind = self._fmi.enumeration_type
                if kind in ("String", "Binary", "Clock"):
                    raise FMUError(f"variable {v.name!r} of FMU {self.model.path.name} is a {v.type}, not a number")
                calls.append((getattr(fmu, "get" + kind), v.valueReference))

            def getter() -> npt.NDArray[np.float64]:
                return np.array([float(g([vr])[0]) for g, vr in calls])
        self._getters[names] = getter
        return getter

    def _setter(self, names: tuple[str, ...]) -> Callable[[Any], None]:
        setter = self._setters.get(names)
        if setter is not None:
            return setter
        fmu = self._fmu
        variables = [self.model.variable(n) for n in names]
        if all(v.type in ("Real", "Float64") for v in variables):
            setter = self._fmi.real_writer([v.valueReference for v in variables])
        else:
            calls = []
            for v in variables:
                kind = v.type
                if kind == "Enumeration":
                    kind = self._fmi.enumeration_type
                py = {"Boolean": bool, "String": str}.get(kind, float if kind in REAL_TYPES else int)
                calls.append((getattr(fmu, "set" + kind), v.valueReference, py))

            def setter(values: Any) -> None:
                for (s, vr, py), value in zip(calls, values):
                    s([vr], [py(value)])
        self._setters[names] = setter
        return setter

    # -- initialisation -----------------------------------------------------------
    def _settable_before_init(self, name: str) -> ModelVariable:
        v = self.model.variable(name)
        if v.causality in ("independent", "calculatedParameter") or v.variability == "constant":
            raise FMUError(f"variable {name!r} of FMU {self.model.path.name} is "
                           f"{v.causality if v.variability != 'constant' else 'a constant'}; it cannot be set")
        if v.causality == "output" or (v.causality == "local" and v.initial not in ("exact", "approx")):
            raise FMUError(f"variable {name!r} of FMU {self.model.path.name} is a computed "
                           f"{v.causality} variable; it cannot be set")
        return v

    def _initialize(self, parameters: dict[str, Any], max_step: float | None) -> None:
        model = self.model
        for name in parameters:
            self._settable_before_init(name)
        # inputs given as constants are not driven by the table any more
        self._drop_inputs(set(parameters))
        restore = model.begin_run(parameters)
        self._given = dict(parameters)
        model.log_messages.clear()
        with fmu_calls(f"initialisation of {model.path.name} at t = {self.time:g} s failed", model.log_messages):
            self._initialization(restore, parameters)
        self._start(max_step)

    def _initialization(self, restore: Mapping[str, Any], values: Mapping[str, Any]) -> None:
        """The FMI calls of an initialisation at :attr:`time` with *values* (and *restore*, set first) applied.

        Values of variables with ``initial = exact/approx`` and inputs are set before
        initialisation mode, the others (parameters computed otherwise by default)
        inside it; inputs driven by the table take their values at :attr:`time`.
        """
        variables = {name: self.model.variable(name) for name in values}
        early = dict(restore)
        early.update({n: values[n] for n, v in variables.items() if v.initial in ("exact", "approx")
                      or v.causality == "input"})
        late = {n: values[n] for n in variables if n not in early}
        self._set_values(early)
        self._fmi.enter_initialization_mode(tolerance=self.model.tolerance, start_time=self.time)
        self._set_values(late)
        self._apply_inputs(self.time)
        self._fmu.exitInitializationMode()
        self._after_initialization()

    def _set_values(self, values: Mapping[str, Any]) -> None:
        if not values:
            return
        names = tuple(values)
        vals = [values[n] for n in names]
        for n, value in zip(names, vals):
            if isinstance(value, str):
                raise FMUError(f"value of {n!r} must be a number, not {value!r}")
        self._setter(names)(vals)

    def _check_open(self) -> None:
        if self._finished or self.model.closed:
            raise FMUError(f"this stepper of {self.model.path.name} is finished "
                           "(the model was closed or a newer run was started)")

    # -- public API -----------------------------------------------------------------
    def finish(self) -> None:
        """Make this stepper unusable (its model starts a newer run or closes).

        Its input table goes at once: the solver's callbacks make reference
        cycles that keep a finished stepper until the cyclic garbage collector
        runs, and a run restarted every checkpoint would otherwise hold one
        copy of a whole week's table per restart.
        """
        self._finished = True
        self._in_table = self._in_times = None
        self._in_set = None

    def step(self, t_next: float) -> None:
        """Integrate from :attr:`time` to *t_next*.

        Raises
        ------
        SimulationError
            The solver failed or the states became non-finite; names the time.
        """
        self._check_open()
        t_next = float(t_next)
        tol = 1e-12 * max(1.0, abs(t_next))
        if t_next < self.time - tol:
            raise SimulationError(f"cannot step {self.model.path.name} back in time from "
                                  f"t = {self.time:g} s to t = {t_next:g} s")
        if t_next <= self.time + tol:
            return
        self._advance(t_next)

    def set(self, values: Mapping[str, float], *, restart: bool = True) -> None:
        """Set parameters and/or inputs before the next step.

        Tunable parameters and inputs change as FMI allows between steps.
        ``fixed`` parameters change on model exchange by a re-initialisation
        that keeps the continuous states (:meth:`ModelExchangeStepper._reinitialize`);
        on co-simulation they are refused with what to do instead
        (:func:`~trackingbox.fmu.info.change_refusal`).
        An input set here is no longer driven by the ``inputs`` table of this run.
        For model exchange, the change is a discontinuity: tunable parameters are
        set in event mode and the solver is re-initialised. With
        ``restart=False`` on a stepper made with ``carry=True``
        (:meth:`FMUModel.stepper`), the integrator is not re-initialised
        when it stands exactly at :attr:`time` and the event left the
        continuous states unchanged: CVODE goes on with its step size, order
        and history, and its error test absorbs the jump in the derivatives
        (for a small change; the caller decides what is small).
        :attr:`ModelExchangeStepper.restarts` and
        :attr:`ModelExchangeStepper.carried` count both outcomes.

        Raises
        ------
        FMUError
            Unknown names, or variables that cannot change during a run.
        """
        self._check_open()
        # values equal to what this method set last time change nothing: no event, no solver restart
        values = {n: v for n, v in values.items() if self._last_set.get(n) != v}
        if not values:
            return
        params = fixed = False
        for name in values:
            v = self.model.variable(name)
            if v.causality == "input":
                continue
            if v.causality == "parameter" and v.variability == "tunable":
                params = True
                continue
            refusal = change_refusal(self.model.info, name, self.model.interface)
            if refusal is not None:
                raise FMUError(refusal)
            fixed = True
        self._drop_inputs(set(values))
        with fmu_calls(f"setting {', '.join(values)} in {self.model.path.name} at t = {self.time:g} s failed",
                        self.model.log_messages):
            if fixed:
                self._reinitialize(values)
            else:
                self._apply_set(values, params, restart)
        self.model.note_changed(n for n in values if self.model.variable(n).causality == "parameter")
        self._last_set.update(values)
        self._given.update(values)

    def _reinitialize(self, values: Mapping[str, Any]) -> None:
        """Change ``fixed`` parameters (with *values*) where FMI allows it: see :class:`ModelExchangeStepper`."""
        raise FMUError(f"{self.model.path.name}: fixed parameters cannot change during a co-simulation run")

    def get(self, names: Sequence[str]) -> npt.NDArray[np.float64]:
        """Current values of *names* as a float array (same order)."""
        self._check_open()
        return self._getter(tuple(names))()

    def reader(self, names: Sequence[str]) -> Callable[[], npt.NDArray[np.float64]]:
        """A function returning the current values of *names* (as :meth:`get`, without its checks).

        For tight loops; valid while this stepper is.
        """
        return self._getter(tuple(names))

    def settle(self, hold: Sequence[str] = ()) -> None:
        """Start from the model's steady state (model exchange only: :meth:`ModelExchangeStepper.settle`)."""
        self._check_open()
        raise FMUError(f"{self.model.path.name} runs as co-simulation: its states cannot be set, so it cannot "
                       "start from a steady state; set [data] initial = \"model\" (its own initial state)")

    @abc.abstractmethod
    def get_continuous_states(self) -> npt.NDArray[np.float64]:
        """The continuous state vector (model exchange only), for checkpoints."""

    @abc.abstractmethod
    def set_continuous_states(self, x: npt.ArrayLike) -> None:
        """Overwrite the continuous state vector (model exchange only); the solver restarts."""

    @property
    def state_names(self) -> list[str]:
        """Names of the continuous states, in state-vector order (model exchange)."""
        md = self._fmi.model_description
        return [d.variable.derivative.name for d in md.derivatives if d.variable.derivative is not None]


class CoSimulationStepper(Stepper):
    """The co-simulation driver: the FMU integrates itself, ``doStep`` by ``doStep``.

    A communication step is split at the input table's sample times. Under the
    ``"hold"`` rule each part is one ``doStep`` with the inputs of its first
    sample. Under ``"linear"`` an FMU that interpolates inputs (FMI 2
    ``canInterpolateInputs``) gets each part's value and slope
    (``fmi2SetRealInputDerivatives``, order 1); any other gets
    :data:`CS_LINEAR_SUBSTEPS` sub-steps per part, each with the ramp's value at
    its midpoint.
    """

    def _interpolates(self) -> bool:
        cs = self._fmi.model_description.coSimulation
        return (not self.model.info.fmi_version.startswith("3") and cs is not None
                and bool(getattr(cs, "canInterpolateInputs", False)))

    def _do_step(self, t0: float, t1: float) -> None:
        result = self._fmu.doStep(currentCommunicationPoint=t0, communicationStepSize=t1 - t0)
        if self._fmi.terminated(result):
            raise SimulationError(f"{self.model.path.name} requested termination at t = {t1:g} s")

    def _advance(self, t_next: float) -> None:
        with fmu_calls(f"simulation of {self.model.path.name} failed in the step from "
                        f"t = {self.time:g} s to t = {t_next:g} s", self.model.log_messages):
            t0 = self.time
            for t1 in self._input_breaks(t0, t_next):
                if self._in_set is None or self._held:
                    self._apply_inputs(t0)
                    self._do_step(t0, t1)
                elif self._interpolates():
                    u0, u1 = self._input_values(t0), self._input_values(t1)
                    self._in_set(u0)
                    vrs = [int(self.model.variable(n).valueReference) for n in self._in_names]
                    self._fmu.setRealInputDerivatives(vrs, [1] * len(vrs), list((u1 - u0) / (t1 - t0)))
                    self._do_step(t0, t1)
                else:
                    edges = np.linspace(t0, t1, CS_LINEAR_SUBSTEPS + 1)
                    for a, b in zip(edges[:-1], edges[1:]):
                        self._in_set(self._input_values(0.5 * (a + b)))
                        self._do_step(float(a), float(b))
                t0 = t1
        self.time = t_next
        self._apply_inputs(self.time)

    def _apply_set(self, values: Mapping[str, Any], parameters_changed: bool, restart: bool = True) -> None:
        self._set_values(values)

    def get_continuous_states(self) -> npt.NDArray[np.float64]:
        """Not available: a co-simulation FMU keeps its states to itself (:class:`FMUError`)."""
        self._check_open()
        raise FMUError(f"{self.model.path.name} runs as co-simulation; its states are not accessible")

    def set_continuous_states(self, x: npt.ArrayLike) -> None:
        """Not available: a co-simulation FMU keeps its states to itself (:class:`FMUError`)."""
        self._check_open()
        raise FMUError(f"{self.model.path.name} runs as co-simulation; its states are not accessible")


#: CVODE's return flags (cvode.h): reached the stop time; found a root
_CV_TSTOP_RETURN = 1
_CV_ROOT_RETURN = 2


def cvode_functions() -> tuple[Any, Any]:
    """``CVodeSetStopTime`` and ``CVodeGetCurrentTime`` from the CVODE library FMPy loads.

    FMPy binds only part of CVODE's API; these two are in the same library
    (SUNDIALS 7, documented in CVODE's user guide, "Optional inputs" and
    "Optional outputs").
    """
    set_stop = getattr(sundials_cvode, "CVodeSetStopTime")
    set_stop.argtypes = [ctypes.c_void_p, sunrealtype]
    set_stop.restype = ctypes.c_int
    current = getattr(sundials_cvode, "CVodeGetCurrentTime")
    current.argtypes = [ctypes.c_void_p, ctypes.POINTER(sunrealtype)]
    current.restype = ctypes.c_int
    return set_stop, current


def cvode_solver_class() -> type:
    """A CVodeSolver whose callbacks report Python errors to CVODE instead of swallowing them.

    Its :meth:`step` can also stop CVODE exactly at the target time (CVODE's
    stop time) instead of stepping past it and interpolating back, so the
    integrator's internal time is the communication point: a small change of
    a parameter or input there can then be carried by the integrator (no
    re-initialisation; see :meth:`ModelExchangeStepper.set`).
    """
    set_stop, current = cvode_functions()

    class _Solver(CVodeSolver):  # type: ignore[misc, valid-type]
        callback_error: BaseException | None = None
        #: stop exactly at each target time (see the class's docstring)
        exact = False

        def step(self, t, tNext):  # noqa: N803 - FMPy's signature
            """Integrate towards *tNext*; ``(root found, roots, time reached)`` as FMPy's ``step``."""
            if self.exact and set_stop(self.cvode_mem, tNext) != 0:
                raise RuntimeError(f"CVodeSetStopTime({tNext!r}) failed")
            if not self.discrete:
                self.get_x(self.px, self.nx)
            reached = sunrealtype(0.0)
            flag = CVode(self.cvode_mem, tNext, self.x, ctypes.byref(reached), CV_NORMAL)
            if not self.discrete:
                self.set_x(self.px, self.nx)
            roots = np.zeros(self.nz, dtype=np.int32)
            if flag < 0:
                raise RuntimeError("CVode error (code %s) in module %s, function %s: %s" % self.error_info)
            if flag == _CV_ROOT_RETURN:
                if CVodeGetRootInfo(self.cvode_mem, np.ctypeslib.as_ctypes(roots)) != 0:
                    raise RuntimeError("CVodeGetRootInfo failed")
            return flag == _CV_ROOT_RETURN, roots, reached.value

        def internal_time(self) -> float:
            """CVODE's own time: where its next step starts (after a stop-time return, the target)."""
            t = sunrealtype(0.0)
            if current(self.cvode_mem, ctypes.byref(t)) != 0:
                return math.nan
            return float(t.value)

        def f(self, t, y, ydot, user_data):  # noqa: D401 - CVODE right-hand side
            try:
                return super().f(t, y, ydot, user_data)
            except BaseException as exc:  # an FMU call failed: stop CVODE cleanly
                self.callback_error = exc
                return -1

        def g(self, t, y, gout, user_data):
            try:
                return super().g(t, y, gout, user_data)
            except BaseException as exc:
                self.callback_error = exc
                return -1

    return _Solver


class NoInput:
    """Placeholder for FMPy's input object (inputs are applied in set_time)."""

    @staticmethod
    def apply(*args: Any, **kwargs: Any) -> None:
        return None


class ModelExchangeStepper(Stepper):
    """The model-exchange driver: CVODE (BDF) integrates the FMU's derivatives.

    Parameter changes, input overrides and state overwrites are discontinuities:
    the integrator is re-initialised after each, unless the stepper carries
    small changes (:meth:`carry`, ``set(..., restart=False)``). Time events
    and state events trigger FMI event iterations.

    Attributes
    ----------
    restarts, carried : int
        Changes made through :meth:`set` that re-initialised the integrator,
        and changes it carried.
    """

    def __init__(self, model: FMUModel, fmi: FMIAdapter, *, start_time: float, parameters: dict[str, Any],
                 inputs: pd.DataFrame | None, max_step: float | None, input_rule: str = "linear") -> None:
        md = fmi.model_description
        self._solver: Any = None
        self._next_event: float | None = None
        self._nx = int(md.numberOfContinuousStates or 0)
        self._nz = int(md.numberOfEventIndicators or 0)
        self._x = np.zeros(max(self._nx, 1))
        self._px = self._x.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        self._x_before = np.zeros_like(self._x)
        self.restarts = 0
        self.carried = 0
        #: changes of ``fixed`` parameters, each a re-initialisation (also counted in :attr:`restarts`)
        self.reinitializations = 0
        #: the held inputs written last ("hold" rule)
        self._held_now: npt.NDArray[np.float64] | None = None
        super().__init__(model, fmi, start_time=start_time, parameters=parameters, inputs=inputs,
                         max_step=max_step, input_rule=input_rule)

    def _after_initialization(self) -> None:
        self._event_iteration(initial=True)
        self._held_now = self._held_values(self.time) if (self._held and self._in_set is not None) else None

    def _start(self, max_step: float | None) -> None:
        fmu = self._fmu
        if max_step is None:
            max_step = float("inf")
            if self._in_times is not None and self._in_times.size > 1:
                max_step = float(np.min(np.diff(self._in_times)))
        solver_cls = cvode_solver_class()
        n, get_x, set_x, get_dx, get_nominals = self._system()
        self._solver = solver_cls(
            nx=n, nz=self._nz,
            get_x=get_x, set_x=set_x,
            get_dx=get_dx,
            get_z=fmu.getEventIndicators,
            get_nominals=get_nominals,
            set_time=self._set_time, input=NoInput(), startTime=self.time,
            maxStep=max_step, relativeTolerance=self.model.tolerance, maxNumSteps=100000,
        )
        self._check_states()

    def _system(self) -> tuple[int, Callable[..., Any], Callable[..., Any], Callable[..., Any], Callable[..., Any]]:
        """What CVODE integrates: its size and the get/set-state, derivative and nominal callbacks."""
        fmu = self._fmu
        return (self._nx, fmu.getContinuousStates, fmu.setContinuousStates, self._fmi.get_derivatives,
                fmu.getNominalsOfContinuousStates)

    def _set_time(self, t: float) -> None:
        self._fmu.setTime(t)
        if self._in_set is not None and not self._held:
            self._in_set(self._input_values(t))

    def _event_iteration(self, initial: bool = False) -> None:
        fmu = self._fmu
        if not initial:
            fmu.enterEventMode()
        self._update_discrete_states()
        fmu.enterContinuousTimeMode()

    def _update_discrete_states(self) -> None:
        needed, terminate = True, False
        next_defined, next_time = False, 0.0
        while needed and not terminate:
            needed, terminate, next_defined, next_time = self._fmi.update_discrete_states()
        if terminate:
            raise SimulationError(f"{self.model.path.name} requested termination at t = {self.time:g} s")
        self._next_event = float(next_time) if next_defined else None

    def _check_states(self) -> None:
        if self._nx == 0:
            return
        self._fmu.getContinuousStates(self._px, self._nx)
        if not np.all(np.isfinite(self._x[: self._nx])):
            md = self._fmi.model_description
            bad = [d.variable.derivative.name for d, ok in zip(md.derivatives, np.isfinite(self._x))
                   if not ok and d.variable.derivative is not None]
            raise SimulationError(f"simulation of {self.model.path.name} produced non-finite states "
                                  f"{', '.join(map(repr, bad)) or ''} at t = {self.time:g} s")

    def _advance(self, t_next: float) -> None:
        if not self._held or self._in_set is None:
            self._integrate(t_next)
            return
        # "hold": the inputs jump at their sample times; integrate part by part, restarting the
        # solver where a held value changes (the step that crossed the jump used the old value up
        # to it, so the state there is right)
        for t1 in self._input_breaks(self.time, t_next):
            u = self._held_values(self.time)
            if not np.array_equal(u, self._held_now):
                self._apply_held(u)
            self._integrate(t1)
            self.time = t1

    def _apply_held(self, u: npt.NDArray[np.float64]) -> None:
        """Write the held inputs *u* at :attr:`time` and restart the solver there (a discontinuity)."""
        assert self._in_set is not None
        with fmu_calls(f"setting the inputs of {self.model.path.name} at t = {self.time:g} s failed",
                        self.model.log_messages):
            self._in_set(u)
            self._solver.reset(self.time)
        self._held_now = np.array(u, copy=True)

    def _integrate(self, t_next: float) -> None:
        fmu, solver = self._fmu, self._solver
        needs_completed = self._fmi.needs_completed_integrator_step()
        while self.time < t_next - 1e-12 * max(1.0, abs(t_next)):
            target = t_next
            if self._next_event is not None and self.time < self._next_event < t_next:
                target = self._next_event
            solver.callback_error = None
            try:
                state_event, _, t_ret = solver.step(self.time, target)
            except Exception as exc:
                cause: object = solver.callback_error or exc
                info = getattr(solver, "error_info", None)
                if solver.callback_error is None and info and len(info) > 3:
                    cause = str(info[3]).strip()
                raise simulation_failure(f"solver failed in {self.model.path.name} between "
                                          f"t = {self.time:g} s and t = {target:g} s", cause,
                                          self.model.log_messages, solver=True) from None
            self.time = float(t_ret)
            with fmu_calls(f"simulation of {self.model.path.name} failed at t = {self.time:g} s",
                            self.model.log_messages):
                self._set_time(self.time)
                step_event = False
                if needs_completed:
                    step_event, terminate = fmu.completedIntegratorStep()
                    if terminate:
                        raise SimulationError(f"{self.model.path.name} requested termination at "
                                              f"t = {self.time:g} s")
                time_event = self._next_event is not None and math.isclose(self.time, self._next_event)
                if state_event or step_event or time_event:
                    self._event_iteration()
                    solver.reset(self.time)
            self._check_states()
        self.time = t_next

    def carry(self) -> None:
        """From now on stop CVODE exactly at every communication point, so small changes can be carried."""
        self._solver.exact = True

    def _at_time(self) -> bool:
        """True if CVODE's internal time is :attr:`time` (it stopped there, or was re-initialised there)."""
        t_int = self._solver.internal_time()
        return abs(t_int - self.time) <= 1e-12 * max(1.0, abs(self.time))

    def _apply_set(self, values: Mapping[str, Any], parameters_changed: bool, restart: bool = True) -> None:
        carry = not restart and self._solver.exact and self._nx > 0 and self._at_time()
        if carry:
            self._fmu.getContinuousStates(self._px, self._nx)
            self._x_before[: self._nx] = self._x[: self._nx]
        if parameters_changed:
            self._fmu.enterEventMode()
            self._set_values(values)
            self._update_discrete_states()
            self._fmu.enterContinuousTimeMode()
        else:
            self._set_values(values)
        if carry:
            # the event must have left the states where CVODE has them, else it restarts
            self._fmu.getContinuousStates(self._px, self._nx)
            carry = bool(np.array_equal(self._x[: self._nx], self._x_before[: self._nx]))
        if carry:
            self.carried += 1
        else:
            self.restarts += 1
            self._solver.reset(self.time)

    def _reinitialize(self, values: Mapping[str, Any]) -> None:
        """Change ``fixed`` parameters between steps, the way FMI allows for model exchange.

        A ``fixed`` parameter may be set only before initialisation. The FMU is
        therefore reset and initialised again at :attr:`time` with every value
        this run was given or has set since (and *values*), then its continuous
        states are overwritten with those it had, an event iteration brings its
        discrete variables and relations (the event indicators' context) in
        line with the restored states, and the integrator restarts. What the
        initialisation computes from the parameters (calculated parameters,
        derived constants) follows the new values; the states continue. Counted
        in :attr:`restarts` and :attr:`reinitializations`.
        """
        x = self._x[: self._nx].copy()
        if self._nx:
            self._fmu.getContinuousStates(self._px, self._nx)
            x = self._x[: self._nx].copy()
        given = {**self._given, **values}
        self._fmu.reset()
        self._initialization({}, given)
        if self._nx:
            self._x[: self._nx] = x
            self._fmu.setContinuousStates(self._px, self._nx)
            if self._nz:
                # relations and discrete variables as the restored states make them
                self._event_iteration()
        self._solver.reset(self.time)
        self.restarts += 1
        self.reinitializations += 1

    #: a steady state is accepted when no state moves by more than this fraction of its scale per hour
    #: (the scale: its magnitude, at least its nominal value)
    STEADY_DRIFT = 1e-6

    def settle(self, hold: Sequence[str] = ()) -> None:
        """Replace the continuous states by the model's steady state at :attr:`time`.

        Solves ``der(x) = 0`` with the parameters and inputs as they are now (the
        inputs at this time under the run's rule), by Powell's hybrid method on
        the FMU's own derivatives (states scaled by their magnitude or nominal
        value), starting from the current states; where that stalls (a stiff model
        far from its steady state), by integrating the model's own settling from
        there (:func:`~trackingbox.fmu.steady.settle_by_integration`). Then an event
        iteration and a solver restart, as after :meth:`set_continuous_states`.
        The FMU's time never moves; the states in *hold* keep their values (:func:`.steady.free_states`).

        Raises
        ------
        SimulationError
            No steady state found (an integrating state, such as a tank level
            whose flows do not balance, has none): names the state that still
            moves and what to do instead.
        """
        from scipy.optimize import root  # scipy.optimize costs 0.2 s of start-up; only steady starts need it

        self._check_open()
        n = self._nx
        if n == 0:
            return
        fmu = self._fmu
        name = self.model.path.name
        dx = np.zeros(n)
        pdx = dx.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        free = free_states(self.state_names, hold, name)
        with fmu_calls(f"finding the steady state of {name} at t = {self.time:g} s failed", self.model.log_messages):
            fmu.getContinuousStates(self._px, n)
            full0 = self._x[:n].copy()
            nominal = np.ones(n)
            fmu.getNominalsOfContinuousStates(nominal.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), n)
            scale = np.maximum(np.abs(full0), np.where(np.isfinite(nominal) & (nominal > 0), nominal, 1.0))[free]
            x0 = full0[free]

            def rate(z: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
                self._x[:n] = spread(full0, free, z * scale)
                fmu.setContinuousStates(self._px, n)
                self._fmi.get_derivatives(pdx, n)
                return dx[free] / scale

            lost: tuple[int, ...] = ()
            with np.errstate(all="ignore"):
                sol = root(rate, x0 / scale, method="hybr",
                           options={"xtol": 1e-13, "maxfev": 200 * (n + 1)})
                z, evaluations, how = sol.x, sol.nfev, " ".join(str(sol.message).split()).rstrip(".")
                drift = np.abs(rate(z)) * 3600.0
                if not (np.all(np.isfinite(z)) and np.all(drift <= self.STEADY_DRIFT)):  # Powell's method stalled
                    run = settle_by_integration(rate, x0 / scale, self.STEADY_DRIFT / 3600.0)
                    z, evaluations = run.z, evaluations + run.evaluations
                    drift = np.abs(rate(z)) * 3600.0
                    how = f"Powell's hybrid method: {how}; the model's own settling: {run.message or 'settled'}"
                    lost = run.nonfinite
            why = no_steady_state([s for s, f in zip(self.state_names, free) if f],
                                  np.where(np.isfinite(z), drift, np.inf), self.STEADY_DRIFT, lost, how)
            if why:
                self._x[:n] = full0
                fmu.setContinuousStates(self._px, n)
                raise SimulationError(f"{name} has no steady state at t = {self.time:g} s with its inputs there: {why}")
            self._x[:n] = spread(full0, free, z * scale)
            fmu.setContinuousStates(self._px, n)
            if self._nz:
                self._event_iteration()
        self._solver.reset(self.time)
        log.debug("%s: steady state at t = %g s after %d evaluations", name, self.time, evaluations)

    def get_continuous_states(self) -> npt.NDArray[np.float64]:
        """The continuous state vector, for checkpoints."""
        self._check_open()
        self._fmu.getContinuousStates(self._px, self._nx)
        return self._x[: self._nx].copy()

    def set_continuous_states(self, x: npt.ArrayLike) -> None:
        """Overwrite the continuous state vector; the solver restarts."""
        self._check_open()
        arr = np.asarray(x, dtype=float).ravel()
        if arr.size != self._nx:
            raise FMUError(f"{self.model.path.name} has {self._nx} continuous states, not {arr.size}")
        self._x[: self._nx] = arr
        self._fmu.setContinuousStates(self._px, self._nx)
        self._solver.reset(self.time)
