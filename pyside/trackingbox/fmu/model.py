"""An FMU extracted and instantiated once, simulated many times: :class:`FMUModel`.

It owns the FMU instance and hands each run a driver behind the one
:class:`~trackingbox.fmu.steppers.Stepper` interface; the two talk only through public methods
(``FMUModel.variable``, ``begin_run``, ``note_changed``; ``Stepper.finish``, ``input_times``,
``reader``).
"""
from __future__ import annotations

import collections
import contextlib
import logging
import math
import os
import shutil
import weakref
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import fmpy
import fmpy.simulation
import numpy as np
import pandas as pd
from fmpy.model_description import ModelVariable

from .. import config
from ..errors import FMUError, SimulationError, unknown_name
from ..native import native_reason
from ..supervise import note_fmu, note_output
from . import isolation
from .adapters import FMI2Adapter, FMI3Adapter, FMIAdapter
from .calls import Messages, fmi3_logger
from .info import Interface, read_info, start_value
from .native_stepper import NativeStepper
from .sensitivities import SensitivityStepper
from .steppers import CoSimulationStepper, ModelExchangeStepper, Stepper

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------
# FMUModel
# ---------------------------------------------------------------------------

def _cleanup(holder: dict[str, Any], tempdir: str | None, pid: int) -> None:
    """Free the FMU instance and delete the extraction directory (also run at GC).

    Only in the process that opened the FMU: a forked worker that drops an
    inherited :class:`FMUModel` must not delete its parent's files.
    """
    if os.getpid() != pid:
        holder.pop("fmu", None)
        return
    fmu = holder.pop("fmu", None)
    if fmu is not None:
        with contextlib.suppress(Exception):
            fmu.freeInstance()
    if tempdir:
        shutil.rmtree(tempdir, ignore_errors=True)
        note_output(tempdir, False)


class FMUModel:
    """An FMU extracted and instantiated once, simulated many times.

    Parameters
    ----------
    path
        The ``.fmu`` file.
    tolerance
        Relative tolerance of the ODE solver (model exchange) and the value
        passed to the FMU at initialisation.
    interface
        ``"ModelExchange"`` or ``"CoSimulation"``; default: model exchange
        when the FMU offers it (we then control the solver), else co-simulation.

    Examples
    --------
    Run one FMU for several parameter values (it is extracted once)::

        with FMUModel("twin.fmu") as model:
            for k in (800.0, 1000.0):
                df = model.simulate(stop_time=3600, output_interval=10, parameters={"hx.kht": k})
    """

    def __init__(self, path: str | Path, *, tolerance: float = 1e-6, interface: Interface | None = None):
        self.path = Path(path)
        self.info = read_info(self.path)
        self.tolerance = float(tolerance)
        md = self.info.model_description
        assert md is not None
        if interface is None:
            interface = "ModelExchange" if md.modelExchange is not None else "CoSimulation"
        if interface not in self.info.interfaces:
            raise FMUError(
                f"FMU {self.path} does not provide the {interface} interface "
                f"(it provides: {', '.join(self.info.interfaces) or 'none'})"
            )
        self.interface: Interface = interface
        if self.info.fmi_version.startswith("1"):
            raise FMUError(f"FMU {self.path} is FMI {self.info.fmi_version}; only FMI 2.0 and 3.0 are supported")

        platforms = fmpy.supported_platforms(str(self.path))
        if fmpy.platform not in platforms and fmpy.platform_tuple not in platforms:
            raise FMUError(
                f"FMU {self.path} has no binary for this platform ({fmpy.platform_tuple}); "
                f"it has: {', '.join(platforms) or 'none'}"
            )

        self._vars: dict[str, ModelVariable] = {}
        for v in md.modelVariables:
            self._vars.setdefault(v.name, v)
        self._holder: dict[str, Any] = {}
        #: what the FMU logged (FMI 3), newest last: error reports read failed asserts from it
        self.log_messages: Messages = collections.deque(maxlen=20)
        self._tempdir: str | None = None
        note_fmu(self.path)
        self._tempdir = isolation.extract(self.path)
        note_fmu(self.path, self._tempdir)  # the watchdog names this FMU if one of its calls hangs
        self._finalizer = weakref.finalize(self, _cleanup, self._holder, self._tempdir, os.getpid())
        try:
            isolation.canary(self.path, self._tempdir, md, interface)
        except BaseException:
            self._finalizer()
            raise
        try:
            # FMI 3: the FMU's log goes to Python logging and is kept for error reports (asserts)
            logger = (fmi3_logger(self.path.name, self.log_messages)
                      if self.info.fmi_version.startswith("3") else None)
            fmu = fmpy.simulation.instantiate_fmu(self._tempdir, md, fmi_type=interface, logger=logger)
        except Exception as exc:
            self._finalizer()
            raise FMUError(f"FMU {self.path} could not be loaded and instantiated: {exc}") from None
        self._holder["fmu"] = fmu
        adapter = FMI3Adapter if self.info.fmi_version.startswith("3") else FMI2Adapter
        self._fmi: FMIAdapter = adapter(fmu, md)
        self._used = False
        self._active: Stepper | None = None
        self._changed: set[str] = set()
        #: why the last model-exchange run is not native (None: it is; see :meth:`stepper`)
        self.native_reason: str | None = None
        log.debug("opened %s (FMI %s, %s) in %s", self.path, self.info.fmi_version, interface, self._tempdir)

    # -- context manager / cleanup ------------------------------------------
    def __enter__(self) -> FMUModel:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Free the FMU instance and delete the extracted files (idempotent)."""
        self._finish_active()
        self._finalizer()

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run."""
        return not self._finalizer.alive

    def _finish_active(self) -> None:
        if self._active is not None:
            self._active.finish()
            self._active = None

    # -- name resolution ----------------------------------------------------
    def variable(self, name: str, what: str = "variable") -> ModelVariable:
        """FMPy's description of the variable *name*.

        Raises
        ------
        FMUError
            No such variable (with a did-you-mean); *what* names the role in the message.
        """
        try:
            return self._vars[name]
        except KeyError:
            raise FMUError(unknown_name(what, name, self._vars, f"FMU {self.path.name}")) from None

    # -- start values changed by runs -------------------------------------------
    def begin_run(self, parameters: Mapping[str, Any]) -> dict[str, Any]:
        """Start values to restore before a run that sets *parameters*.

        Returns the declared start value of every variable an earlier run changed
        and this run does not set (robust against FMUs whose ``reset`` is
        partial), and records *parameters* as changed by this run.
        """
        restore = [n for n in self._changed if n not in parameters and self._vars[n].start is not None]
        self._changed = set(parameters)
        return {n: start_value(self._vars[n]) for n in restore}

    def note_changed(self, names: Iterable[str]) -> None:
        """Record that the running run changed the parameters *names* (restored at the next run)."""
        self._changed.update(names)

    # -- runs -----------------------------------------------------------------
    def stepper(
        self,
        *,
        start_time: float = 0.0,
        parameters: Mapping[str, float] | None = None,
        inputs: pd.DataFrame | None = None,
        max_step: float | None = None,
        carry: bool = False,
        native: bool | None = None,
        keep_jacobian: bool = False,
        input_rule: str = "linear",
    ) -> Stepper:
        """Initialise a new run at *start_time* and return its :class:`Stepper`.

        Any previous stepper of this model becomes unusable (one FMU instance).
        The stepper is a :class:`ModelExchangeStepper` or a
        :class:`CoSimulationStepper`, after :attr:`interface`.

        Parameters
        ----------
        start_time
            Simulation start time (s).
        parameters
            Values set before initialisation: parameters (fixed or tunable),
            start values of states (``initial="exact"``), or constant inputs.
        inputs
            Table with a ``time`` column (s) and FMU input columns; between
            samples as *input_rule* says, held constant before the first and
            after the last sample.
        max_step
            Largest internal solver step (model exchange); default: the smallest
            spacing of the input samples (so no input feature is stepped over).
        carry
            Model exchange: stop CVODE exactly at every communication point
            (its stop time) instead of letting it step past and interpolate
            back, so that :meth:`Stepper.set` with ``restart=False`` can carry
            the integrator across a small change (no re-initialisation).
            Without it every change restarts the integrator.
        native
            Model exchange: integrate with :class:`~trackingbox.native.NativeStepper`
            (CVODE and the FMU's right-hand side in C, same settings and
            results). ``None`` (default): where the FMU allows it (event-free
            FMI 3 with states, a C compiler at hand) unless the environment
            variable ``TRACKINGBOX_NATIVE`` is ``0``; otherwise the Python path,
            and the reason is logged at debug level and kept in
            :attr:`native_reason`. ``True``: native or :class:`FMUError` saying
            why not. ``False``: the Python path.
        keep_jacobian
            :class:`~trackingbox.native.NativeStepper` only: the first step
            after a change that re-initialises CVODE reuses CVODE's last
            Jacobian instead of evaluating a new one (see
            :meth:`~trackingbox.native.NativeStepper.keep_jacobian`); the
            trajectory stays within the solver's tolerance of the one without
            it, not bit for bit. Ignored on the Python path.
        input_rule
            How the *inputs* table reaches the FMU between its samples (the
            spec's ``[data] inputs``): ``"linear"`` interpolated, ``"hold"`` held
            at the last sample; the same on both interfaces (see
            :class:`~trackingbox.fmu.steppers.CoSimulationStepper`).
        """
        if self.closed:
            raise FMUError(f"FMU {self.path} is closed")
        self._finish_active()
        if self._used:
            try:
                self._fmi.instance.reset()
            except Exception as exc:
                raise FMUError(f"FMU {self.path}: reset failed: {exc}") from None
        self._used = True
        driver = self._driver(native)
        stepper = driver(self, self._fmi, start_time=float(start_time), parameters=dict(parameters or {}),
                         inputs=inputs, max_step=max_step, input_rule=input_rule)
        if carry and isinstance(stepper, ModelExchangeStepper):
            stepper.carry()
        if keep_jacobian and hasattr(stepper, "keep_jacobian"):
            stepper.keep_jacobian()
        self._active = stepper
        return stepper

    def _driver(self, native: bool | None) -> type[Stepper]:
        """The stepper class for a new run (see :meth:`stepper`'s *native*); sets :attr:`native_reason`."""
        if self.interface != "ModelExchange":
            self.native_reason = f"{self.path.name} runs as co-simulation"
            if native:
                raise FMUError(f"no native stepper for {self.path.name}: {self.native_reason}")
            return CoSimulationStepper
        if native is False:
            self.native_reason = "not asked for (native=False)"
            return ModelExchangeStepper
        if native is None and not config.get("native"):
            self.native_reason = "TRACKINGBOX_NATIVE=0"
        else:
            self.native_reason = native_reason(self)
            if self.native_reason is None:
                return NativeStepper
        if native:
            raise FMUError(f"no native stepper for {self.path.name}: {self.native_reason}")
        log.debug("%s: Python model-exchange stepper (%s)", self.path.name, self.native_reason)
        return ModelExchangeStepper

    def sensitivity_stepper(
        self,
        wrt: Sequence[str],
        scales: Sequence[float],
        *,
        start_time: float = 0.0,
        parameters: Mapping[str, float] | None = None,
        inputs: pd.DataFrame | None = None,
        max_step: float | None = None,
        input_rule: str = "linear",
    ) -> SensitivityStepper:
        """Initialise a run that also integrates the sensitivities w.r.t. the tunable parameters *wrt*.

        As :meth:`stepper` (model exchange only); *scales* (one positive number
        per parameter, e.g. its bound range) scale the sensitivity equations
        (:class:`SensitivityStepper`). Check :func:`directional_derivatives_reason`
        first: this does not.
        """
        if self.closed:
            raise FMUError(f"FMU {self.path} is closed")
        if self.interface != "ModelExchange":
            raise FMUError(f"FMU {self.path} runs as co-simulation: its states and directional derivatives "
                           "are not accessible")
        self._finish_active()
        if self._used:
            try:
                self._fmi.instance.reset()
            except Exception as exc:
                raise FMUError(f"FMU {self.path}: reset failed: {exc}") from None
        self._used = True
        stepper = SensitivityStepper(self, self._fmi, start_time=float(start_time),
                                     parameters=dict(parameters or {}), inputs=inputs, max_step=max_step,
                                     wrt=wrt, scales=scales, input_rule=input_rule)
        self._active = stepper
        return stepper

    def simulate(
        self,
        *,
        start_time: float = 0.0,
        stop_time: float,
        output_interval: float,
        inputs: pd.DataFrame | None = None,
        parameters: Mapping[str, float] | None = None,
        outputs: Sequence[str] | None = None,
        input_rule: str = "linear",
        initial: str = "model",
        note: Callable[[float], None] | None = None,
        hold: Sequence[str] = (),
    ) -> pd.DataFrame:
        """Simulate from *start_time* to *stop_time* and sample every *output_interval*.

        Built on :class:`Stepper`: the communication points are the output grid
        plus every input sample time inside the interval (so co-simulation FMUs
        see every input sample). *input_rule* as for :meth:`stepper`.
        *initial* ``"model"``: the FMU's own initial state at *start_time*;
        ``"steady"``: its steady state there, with the inputs at their first
        values (:meth:`~trackingbox.fmu.steppers.ModelExchangeStepper.settle`), the
        states named in *hold* kept at their start values (which *parameters* may set).
        *note*, if given, is called with each communication point before the
        step towards it (e.g. to name the phase of the run for the watchdog).

        Returns
        -------
        pandas.DataFrame
            Column ``time`` then one column per requested variable (default:
            all outputs).

        Raises
        ------
        FMUError
            Unknown variable names (with a did-you-mean).
        SimulationError
            The solver failed or produced non-finite values; names the time.
        """
        start_time = float(start_time)
        stop_time = float(stop_time)
        output_interval = float(output_interval)
        if not (math.isfinite(start_time) and math.isfinite(stop_time)) or stop_time < start_time:
            raise FMUError(f"stop time {stop_time} must not be before start time {start_time}")
        if not (output_interval > 0 and math.isfinite(output_interval)):
            raise FMUError(f"output interval must be a positive number, not {output_interval}")
        names = list(outputs) if outputs is not None else self.info.outputs
        for name in names:
            self.variable(name, "output variable")
        n = int(math.floor((stop_time - start_time) / output_interval + 1e-9))
        grid = start_time + output_interval * np.arange(n + 1)
        if grid[-1] < stop_time - 1e-9 * max(1.0, abs(stop_time)):
            grid = np.append(grid, stop_time)
        points = grid
        stepper = self.stepper(start_time=start_time, parameters=parameters, inputs=inputs, input_rule=input_rule)
        if initial == "steady":
            stepper.settle(hold=tuple(hold))
        elif initial != "model":
            raise FMUError(f"initial state must be 'model' or 'steady', not {initial!r}")
        input_times = stepper.input_times
        if input_times is not None and input_times.size:
            extra = input_times[(input_times > start_time) & (input_times < stop_time)]
            points = np.union1d(grid, extra)
        record = np.isin(points, grid)
        rows = np.empty((grid.size, len(names)))
        read = stepper.reader(names)
        j = 0
        for t, keep in zip(points, record):
            if note is not None:
                note(float(t))
            stepper.step(float(t))
            if keep:
                rows[j] = read()
                j += 1
        bad = ~np.isfinite(rows)
        if bad.any():
            i, c = np.argwhere(bad)[0]
            raise SimulationError(
                f"simulation of {self.path.name} produced a non-finite value of {names[c]!r} "
                f"at t = {grid[i]:g} s"
            )
        df = pd.DataFrame(rows, columns=names)
        df.insert(0, "time", grid)
        return df
