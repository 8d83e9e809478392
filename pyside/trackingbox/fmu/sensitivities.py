"""Forward sensitivities of the states w.r.t. tunable parameters (model exchange, directional
derivatives): :class:`SensitivityStepper`, :func:`directional_derivatives_reason`.
"""
from __future__ import annotations

import ctypes
import logging
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from fmpy.sundials.libraries import sundials_cvode, sundials_sunmatrixdense
from fmpy.sundials.nvector_serial import NV_DATA_S
from fmpy.sundials.sundials_matrix import SUNMatrix
from fmpy.sundials.sundials_nvector import N_Vector

from ..errors import FMUError
from .adapters import FMIAdapter
from .calls import fmu_calls
from .info import REAL_TYPES, FMUInfo, Interface
from .steppers import ModelExchangeStepper

if TYPE_CHECKING:
    from .model import FMUModel

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------
# forward sensitivities (model exchange, directional derivatives)
# ---------------------------------------------------------------------------

def directional_derivatives_reason(info: FMUInfo, interface: Interface = "ModelExchange") -> str | None:
    """Why the FMU's directional derivatives cannot give exact parameter sensitivities, or None if they can.

    Needs the model-exchange interface with ``providesDirectionalDerivatives``
    (FMI 3) / ``providesDirectionalDerivative`` (FMI 2), at least one continuous
    state, and no initial unknown the FMU computes from the parameters (a state
    or parameter solved by initial equations: its dependence on the parameters
    is not in the derivatives of the continuous-time equations, and the
    sensitivities would start wrong). Whether the FMU also accepts parameters
    as knowns is checked at run time (:meth:`SensitivityStepper.check_parameter_derivatives`).

    >>> info = FMUInfo(Path("cs.fmu"), "2.0", "M", ("CoSimulation",), ())
    >>> directional_derivatives_reason(info)
    'cs.fmu has no model-exchange interface'
    """
    md = info.model_description
    if interface != "ModelExchange" or "ModelExchange" not in info.interfaces:
        return f"{info.path.name} has no model-exchange interface"
    if md is None or md.modelExchange is None:
        return f"{info.path.name}: no model description read"
    me = md.modelExchange
    flag = ("providesDirectionalDerivatives" if info.fmi_version.startswith("3")
            else "providesDirectionalDerivative")
    if not (bool(getattr(me, "providesDirectionalDerivative", False)) or _declares(info.path, flag)):
        return f"{info.path.name} does not declare {flag}"
    if not md.derivatives:
        return f"{info.path.name} has no continuous states"
    states = {d.variable.derivative.name for d in md.derivatives if d.variable.derivative is not None}
    solved = [v.name for v in md.modelVariables
              if (v.causality == "calculatedParameter" and v.initial == "calculated")
              or (v.name in states and v.initial in ("approx", "calculated"))]
    if solved:
        return (f"{info.path.name} computes {', '.join(solved[:3])}{' ...' if len(solved) > 3 else ''} "
                "at initialisation (initial equations)")
    return None


def _declares(path: Path, flag: str) -> bool:
    """Whether the ``<ModelExchange>`` element of *path*'s model description sets *flag* to true.

    fmpy 0.3.32 reads FMI 3's ``providesDirectionalDerivatives`` under FMI 2's
    singular name and so never sees it; this reads the one attribute itself.
    """
    try:
        with zipfile.ZipFile(path) as zf, zf.open("modelDescription.xml") as fh:
            for _, element in ET.iterparse(fh, events=("start",)):
                if element.tag == "ModelExchange":
                    return str(element.get(flag, "false")).strip().lower() in ("true", "1")
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
        return False
    return False


class SensitivityStepper(ModelExchangeStepper):
    """Model exchange with the forward sensitivities of the states w.r.t. tunable parameters.

    CVODE integrates the states and, with them, the sensitivity equations

    ``dS_j/dt = (df/dx) S_j + (df/dp_j) s_j``,  ``S_j = (dx/dp_j) s_j``,

    one block per parameter ``p_j`` scaled by ``s_j`` (so that ``S_j`` has the
    units and the nominal values of the states, and CVODE's error test treats
    it as it treats them). Each block's right-hand side is one directional
    derivative of the FMU: unknowns the state derivatives, knowns the states and
    ``p_j``, seed ``(S_j, s_j)``. The sensitivities start at zero (the states'
    start values do not depend on the parameters; see
    :func:`directional_derivatives_reason`). Outputs' sensitivities are
    ``(dy/dx) S_j / s_j + dy/dp_j`` (:meth:`output_sensitivities`), one more
    directional derivative per parameter.
    """

    #: Absolute tolerance of the sensitivity blocks relative to the states' (their nominals times
    #: the relative tolerance); 1 would control their error as tightly as the states'. Measured on
    #: the heat-exchanger bench twin (8 h run, rtol 1e-6, dx/dkht against a central difference at
    #: rtol 1e-10): factor 1 -> 3.7e-5 relative error at 4.0x the CPU of a plain run, 10 -> 4.8e-5
    #: at 2.6x, 100 -> 1.1e-4 at 1.7x, 1e4 -> 1.4e-4 at 1.7x (the steps are then the states'). The
    #: forward difference it replaces (step 1e-3 of the range) is off by 0.15 there.
    sensitivity_tolerance = 100.0

    def __init__(self, model: FMUModel, fmi: FMIAdapter, *, start_time: float, parameters: dict[str, Any],
                 inputs: pd.DataFrame | None, max_step: float | None, wrt: Sequence[str],
                 scales: Sequence[float]) -> None:
        md = fmi.model_description
        nx = int(md.numberOfContinuousStates or 0)
        if nx == 0 or not md.derivatives:
            raise FMUError(f"{model.path.name} has no continuous states: no sensitivity equations to integrate")
        self._wrt = [str(n) for n in wrt]
        self._scales = np.asarray(scales, dtype=float)
        if self._scales.shape != (len(self._wrt),) or not np.all(np.isfinite(self._scales) & (self._scales > 0)):
            raise FMUError(f"sensitivity scales must be {len(self._wrt)} positive numbers, not {scales!r}")
        self._param_vr = []
        for name in self._wrt:
            v = model.variable(name, "parameter")
            if v.causality != "parameter" or v.variability != "tunable" or v.type not in REAL_TYPES:
                raise FMUError(f"variable {name!r} of FMU {model.path.name} is {v.variability} {v.causality} "
                               f"({v.type}): sensitivities are taken w.r.t. tunable Real parameters only")
            self._param_vr.append(int(v.valueReference))
        self._state_vr = [int(d.variable.derivative.valueReference) for d in md.derivatives]
        self._der_vr = [int(d.variable.valueReference) for d in md.derivatives]
        self._S = np.zeros((len(self._wrt), nx))
        self._seed = np.zeros(nx + 1)
        self._out_calls: dict[tuple[str, ...], list[Callable[[Any], npt.NDArray[np.float64]]]] = {}
        self._jac_call: Callable[[Any], npt.NDArray[np.float64]] | None = None
        #: directional-derivative calls made so far (sensitivity equations and outputs)
        self.directional_calls = 0
        super().__init__(model, fmi, start_time=start_time, parameters=parameters, inputs=inputs,
                         max_step=max_step)

    @property
    def parameters(self) -> list[str]:
        """The parameters the sensitivities are taken with respect to."""
        return list(self._wrt)

    def _system(self) -> tuple[int, Callable[..., Any], Callable[..., Any], Callable[..., Any], Callable[..., Any]]:
        fmu, nx, m = self._fmu, self._nx, len(self._wrt)
        n = nx * (1 + m)
        S, seed, scales = self._S, self._seed, self._scales
        calls = [self._fmi.directional(self._der_vr, self._state_vr + [vr]) for vr in self._param_vr]
        get_derivatives = self._fmi.get_derivatives
        views: dict[int, npt.NDArray[np.float64]] = {}

        def view(ptr: Any) -> npt.NDArray[np.float64]:
            # CVODE passes the same few vectors again and again: one numpy view per address
            address = ctypes.addressof(ptr.contents)
            found = views.get(address)
            if found is None:
                found = views[address] = np.ctypeslib.as_array(ptr, (n,))
            return found

        def get_x(ptr: Any, size: int) -> None:
            fmu.getContinuousStates(ptr, nx)
            view(ptr)[nx:] = S.ravel()

        def set_x(ptr: Any, size: int) -> None:
            fmu.setContinuousStates(ptr, nx)
            S[:] = view(ptr)[nx:].reshape(m, nx)

        def get_dx(ptr: Any, size: int) -> None:
            get_derivatives(ptr, nx)
            out = view(ptr)
            for j, call in enumerate(calls):
                seed[:nx] = S[j]
                seed[nx] = scales[j]
                out[nx * (j + 1): nx * (j + 2)] = call(seed)
            self.directional_calls += m

        def get_nominals(ptr: Any, size: int) -> None:
            fmu.getNominalsOfContinuousStates(ptr, nx)
            out = np.ctypeslib.as_array(ptr, (n,))
            out[nx:] = np.tile(out[:nx], m) * self.sensitivity_tolerance

        return n, get_x, set_x, get_dx, get_nominals

    def _start(self, max_step: float | None) -> None:
        super()._start(max_step)
        self._jac_fn = _block_jacobian(self)  # kept referenced while CVODE may call it
        _set_jacobian(self._solver, self._jac_fn)

    def state_jacobian(self) -> npt.NDArray[np.float64]:
        """``d(der x)/dx`` at the current time and states: one directional derivative per state."""
        nx = self._nx
        call = self._jac_call
        if call is None:
            call = self._jac_call = self._fmi.directional(self._der_vr, self._state_vr)
        out = np.empty((nx, nx))
        seed = np.zeros(nx)
        for i in range(nx):
            seed[i] = 1.0
            out[:, i] = call(seed)
            seed[i] = 0.0
        self.directional_calls += nx
        return out

    def state_sensitivities(self) -> npt.NDArray[np.float64]:
        """``dx/dp`` now: shape (number of states, number of parameters)."""
        self._check_open()
        return (self._S / self._scales[:, None]).T.copy()

    def output_sensitivities(self, names: Sequence[str]) -> npt.NDArray[np.float64]:
        """``dy/dp`` of the variables *names* now: shape (len(names), number of parameters)."""
        self._check_open()
        key = tuple(names)
        calls = self._out_calls.get(key)
        if calls is None:
            vrs = [int(self.model.variable(n, "output variable").valueReference) for n in key]
            calls = [self._fmi.directional(vrs, self._state_vr + [vr]) for vr in self._param_vr]
            self._out_calls[key] = calls
        nx, seed = self._nx, self._seed
        out = np.empty((len(key), len(calls)))
        with fmu_calls(f"directional derivatives of {self.model.path.name} failed at t = {self.time:g} s",
                        self.model.log_messages):
            for j, call in enumerate(calls):
                seed[:nx] = self._S[j]
                seed[nx] = self._scales[j]
                out[:, j] = call(seed) / self._scales[j]
        self.directional_calls += len(calls)
        return out

    def check_parameter_derivatives(self, relative_step: float = 1e-6) -> dict[str, float]:
        """How far the FMU's ``d(der x)/dp_j`` is from a central difference, per parameter, now.

        Each parameter is moved by ``relative_step`` times its scale either way
        (in event mode, as :meth:`set` does), the state derivatives read, and the
        parameter restored; the solver restarts. Returns, per parameter, the
        largest absolute mismatch divided by the largest magnitude of either
        vector (0 where both vanish). An FMU that ignores a parameter seed (it
        exports derivatives w.r.t. states and inputs only) shows 1 here.
        """
        self._check_open()
        nx = self._nx
        buf = np.zeros(nx)
        pbuf = buf.ctypes.data_as(ctypes.POINTER(ctypes.c_double))
        out: dict[str, float] = {}
        with fmu_calls(f"checking the directional derivatives of {self.model.path.name} failed",
                        self.model.log_messages):
            for name, vr, scale in zip(self._wrt, self._param_vr, self._scales):
                seed = np.zeros(nx + 1)
                seed[nx] = 1.0
                exact = self._fmi.directional(self._der_vr, self._state_vr + [vr])(seed)
                value = float(self.get([name])[0])
                h = relative_step * scale
                rows = []
                for v in (value + h, value - h):
                    self._apply_set({name: v}, True)
                    self._fmi.get_derivatives(pbuf, nx)
                    rows.append(buf.copy())
                self._apply_set({name: value}, True)
                fd = (rows[0] - rows[1]) / (2 * h)
                size = max(float(np.max(np.abs(fd))), float(np.max(np.abs(exact))))
                out[name] = float(np.max(np.abs(exact - fd)) / size) if size > 0 else 0.0
        return out


def _block_jacobian(stepper: SensitivityStepper) -> Any:
    """CVODE's Jacobian callback for the augmented system: ``d(der x)/dx`` repeated on the diagonal.

    The exact Jacobian of the sensitivity blocks also has ``d((df/dx) S_j)/dx`` below
    the diagonal; leaving it out (as CVODES's simultaneous corrector does) changes
    only the Newton iteration's convergence rate, never the solution, which the
    corrector's own convergence and error tests govern. It costs ``nx``
    directional derivatives instead of ``nx * (1 + m)`` right-hand sides.
    """
    data_of = sundials_sunmatrixdense.SUNDenseMatrix_Data
    data_of.argtypes = [SUNMatrix]
    data_of.restype = ctypes.POINTER(ctypes.c_double)
    prototype = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double, N_Vector, N_Vector, SUNMatrix, ctypes.c_void_p,
                                 N_Vector, N_Vector, N_Vector)
    nx, m = stepper._nx, len(stepper._wrt)
    n = nx * (1 + m)
    solver = stepper._solver

    def jac(t: float, y: Any, fy: Any, matrix: Any, user_data: Any, tmp1: Any, tmp2: Any, tmp3: Any) -> int:
        try:
            solver.set_time(t)
            solver.set_x(NV_DATA_S(y), n)
            block = stepper.state_jacobian()
            a = np.ctypeslib.as_array(data_of(matrix), (n, n))  # row k holds column k (column-major)
            a[:] = 0.0
            for b in range(m + 1):
                a[b * nx:(b + 1) * nx, b * nx:(b + 1) * nx] = block.T
            return 0
        except BaseException as exc:  # an FMU call failed: stop CVODE cleanly (reported as a solver failure)
            solver.callback_error = exc
            return -1

    return prototype(jac)


def _set_jacobian(solver: Any, jac: Any) -> None:
    set_jac = sundials_cvode.CVodeSetJacFn
    set_jac.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
    set_jac.restype = ctypes.c_int
    flag = set_jac(solver.cvode_mem, ctypes.cast(jac, ctypes.c_void_p))
    if flag != 0:
        raise FMUError(f"CVodeSetJacFn failed (flag {flag})")
