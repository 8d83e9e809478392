"""The FMU layer: read an FMU's interface, simulate it, step it in time.

A thin wrapper around FMPy. The model description is FMPy's
:class:`fmpy.model_description.ModelDescription`; this module only adds

* :func:`read_info`: the variables of an FMU as small frozen records, with
  errors that name the file and the problem (:class:`~trackingbox.errors.FMUError`);
* :class:`FMUModel`: extract and instantiate an FMU *once* and run it many
  times (``reset`` between runs, never re-extract);
* :class:`Stepper`: advance one communication step at a time and change tunable
  parameters and inputs between steps, as the tracking loop does.

Modules, each one concern, lower layers first (none imports a later one):

* :mod:`.info`: :class:`FMUInfo`, :class:`Variable`, :func:`read_info`, :func:`check_values`;
* :mod:`.calls`: every failure the FMU or the solver reports becomes a
  :class:`~trackingbox.errors.SimulationError` in one place (:func:`~.calls.simulation_failure`);
* :mod:`.adapters`: what differs between FMI 2 and FMI 3 (``FMI2Adapter``/``FMI3Adapter``);
* :mod:`.isolation`: bounded extraction and the canary run of a foreign binary;
* :mod:`.steppers`: :class:`Stepper`, :class:`ModelExchangeStepper` (CVODE),
  :class:`CoSimulationStepper` (``doStep``);
* :mod:`.sensitivities`: :class:`SensitivityStepper`, :func:`directional_derivatives_reason`;
* :mod:`.native_stepper`: :class:`NativeStepper`, the model-exchange stepper whose steps run in
  the C library of :mod:`trackingbox.native`;
* :mod:`.model`: :class:`FMUModel`, which owns the instance and hands each run a driver.

:class:`FMUModel` and the drivers talk only through public methods
(``FMUModel.variable``, ``begin_run``, ``note_changed``; ``Stepper.finish``,
``input_times``, ``reader``).

Model exchange FMUs (FMI 2 and FMI 3) are integrated with CVODE (BDF, dense
direct solver) from FMPy's bundled SUNDIALS; after every parameter change,
input override or state overwrite the integrator is re-initialised, because such
a change is a discontinuity. Co-simulation FMUs (FMI 2 and FMI 3) are advanced
with ``doStep``.
"""
from __future__ import annotations

from .calls import Messages
from .info import (
    MAX_DESCRIPTION_BYTES,
    MAX_ENTRIES,
    MAX_EXTRACTED_BYTES,
    FMUInfo,
    Interface,
    Variable,
    check_values,
    read_info,
)
from .isolation import CANARY_TIMEOUT
from .model import FMUModel
from .native_stepper import NativeStepper
from .sensitivities import SensitivityStepper, directional_derivatives_reason
from .steppers import CoSimulationStepper, ModelExchangeStepper, Stepper

__all__ = [
    "CANARY_TIMEOUT", "MAX_DESCRIPTION_BYTES", "MAX_ENTRIES", "MAX_EXTRACTED_BYTES", "CoSimulationStepper",
    "FMUInfo", "FMUModel", "Interface", "Messages", "ModelExchangeStepper", "NativeStepper", "SensitivityStepper",
    "Stepper", "Variable", "check_values", "directional_derivatives_reason", "read_info",
]
