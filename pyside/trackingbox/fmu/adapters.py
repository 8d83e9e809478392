"""What differs between FMI 2 and FMI 3, in two thin adapters behind one interface.

Typed Real access, initialisation, event iteration, the derivative call and the
termination flags: :class:`FMI2Adapter` and :class:`FMI3Adapter`, both :class:`FMIAdapter`.
"""
from __future__ import annotations

import abc
import ctypes
import logging
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from fmpy.model_description import ModelDescription

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------
# FMI 2 / FMI 3 adapters
# ---------------------------------------------------------------------------

class FMIAdapter(abc.ABC):
    """What differs between FMI 2 and FMI 3 for the drivers, on one FMPy instance.

    Everything else (``reset``, ``setTime``, ``doStep``, the continuous-state
    calls, the typed ``get*``/``set*``) has the same name in FMPy's FMI 2 and
    FMI 3 classes and is called on :attr:`instance` directly.
    """

    #: FMI type name under which an enumeration is read and written.
    enumeration_type = "Integer"

    def __init__(self, instance: Any, model_description: ModelDescription) -> None:
        self.instance = instance
        self.model_description = model_description

    @abc.abstractmethod
    def real_reader(self, value_references: Sequence[int]) -> Callable[[], npt.NDArray[np.float64]]:
        """A fast reader of these Real/Float64 variables (one C call, values copied)."""

    @abc.abstractmethod
    def real_writer(self, value_references: Sequence[int]) -> Callable[[Any], None]:
        """A fast writer of these Real/Float64 variables (one C call)."""

    @abc.abstractmethod
    def enter_initialization_mode(self, *, tolerance: float, start_time: float) -> None:
        """Enter initialisation mode with the run's tolerance and start time."""

    @abc.abstractmethod
    def update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        """One event-iteration call: ``(needed, terminate, next_event_defined, next_event_time)``."""

    @property
    @abc.abstractmethod
    def get_derivatives(self) -> Callable[..., Any]:
        """FMPy's call filling the state-derivative vector (model exchange)."""

    @abc.abstractmethod
    def needs_completed_integrator_step(self) -> bool:
        """Whether ``completedIntegratorStep`` must be called after each solver step (model exchange)."""

    def terminated(self, do_step_result: Any) -> bool:
        """Whether a ``doStep`` result says the FMU asked to terminate (co-simulation)."""
        return False

    @abc.abstractmethod
    def directional(self, unknowns: Sequence[int], knowns: Sequence[int]
                    ) -> Callable[[Any], npt.NDArray[np.float64]]:
        """A fast ``seed -> sensitivity`` of the FMU's directional derivative (one C call, values copied).

        ``sensitivity = (d unknowns / d knowns) @ seed`` at the current point.
        """


def _buffer(value_references: Sequence[int]) -> tuple[int, Any, npt.NDArray[np.float64], Any]:
    n = len(value_references)
    vr = (ctypes.c_uint32 * n)(*value_references)
    buf = np.zeros(n)
    return n, vr, buf, buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


class FMI2Adapter(FMIAdapter):
    enumeration_type = "Integer"

    def real_reader(self, value_references: Sequence[int]) -> Callable[[], npt.NDArray[np.float64]]:
        n, vr, buf, pbuf = _buffer(value_references)
        func, comp = self.instance.fmi2GetReal, self.instance.component

        def read() -> npt.NDArray[np.float64]:
            func(comp, vr, n, pbuf)
            return buf.copy()
        return read

    def real_writer(self, value_references: Sequence[int]) -> Callable[[Any], None]:
        n, vr, buf, pbuf = _buffer(value_references)
        func, comp = self.instance.fmi2SetReal, self.instance.component

        def write(values: Any) -> None:
            buf[:] = values
            func(comp, vr, n, pbuf)
        return write

    def enter_initialization_mode(self, *, tolerance: float, start_time: float) -> None:
        self.instance.setupExperiment(tolerance=tolerance, startTime=start_time)
        self.instance.enterInitializationMode()

    def update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        needed, terminate, _, _, next_defined, next_time = self.instance.newDiscreteStates()
        return needed, terminate, next_defined, next_time

    @property
    def get_derivatives(self) -> Callable[..., Any]:
        return self.instance.getDerivatives

    def needs_completed_integrator_step(self) -> bool:
        # FMI 2 asks for the call with needsCompletedIntegratorStep
        return bool(self.model_description.modelExchange.needsCompletedIntegratorStep)

    def directional(self, unknowns: Sequence[int], knowns: Sequence[int]
                    ) -> Callable[[Any], npt.NDArray[np.float64]]:
        nu, vu, out, pout = _buffer(unknowns)
        nk, vk, seed, pseed = _buffer(knowns)
        func, comp = self.instance.fmi2GetDirectionalDerivative, self.instance.component

        def call(values: Any) -> npt.NDArray[np.float64]:
            seed[:] = values
            func(comp, vu, nu, vk, nk, pseed, pout)
            return out.copy()
        return call


class FMI3Adapter(FMIAdapter):
    enumeration_type = "Int64"

    def real_reader(self, value_references: Sequence[int]) -> Callable[[], npt.NDArray[np.float64]]:
        n, vr, buf, pbuf = _buffer(value_references)
        func, comp = self.instance.fmi3GetFloat64, self.instance.component

        def read() -> npt.NDArray[np.float64]:
            func(comp, vr, n, pbuf, n)
            return buf.copy()
        return read

    def real_writer(self, value_references: Sequence[int]) -> Callable[[Any], None]:
        n, vr, buf, pbuf = _buffer(value_references)
        func, comp = self.instance.fmi3SetFloat64, self.instance.component

        def write(values: Any) -> None:
            buf[:] = values
            func(comp, vr, n, pbuf, n)
        return write

    def enter_initialization_mode(self, *, tolerance: float, start_time: float) -> None:
        self.instance.enterInitializationMode(tolerance=tolerance, startTime=start_time)

    def update_discrete_states(self) -> tuple[bool, bool, bool, float]:
        needed, terminate, _, _, next_defined, next_time = self.instance.updateDiscreteStates()
        return needed, terminate, next_defined, next_time

    @property
    def get_derivatives(self) -> Callable[..., Any]:
        return self.instance.getContinuousStateDerivatives

    def needs_completed_integrator_step(self) -> bool:
        # FMI 3 waives the call with completedIntegratorStepNotNeeded
        return not self.model_description.modelExchange.completedIntegratorStepNotNeeded

    def terminated(self, do_step_result: Any) -> bool:
        return do_step_result is not None and bool(do_step_result[1])

    def directional(self, unknowns: Sequence[int], knowns: Sequence[int]
                    ) -> Callable[[Any], npt.NDArray[np.float64]]:
        nu, vu, out, pout = _buffer(unknowns)
        nk, vk, seed, pseed = _buffer(knowns)
        func, comp = self.instance.fmi3GetDirectionalDerivative, self.instance.component

        def call(values: Any) -> npt.NDArray[np.float64]:
            seed[:] = values
            func(comp, vu, nu, vk, nk, pseed, nk, pout, nu)
            return out.copy()
        return call
