"""A native model-exchange stepper: CVODE and the FMU's right-hand side with no Python inside a step.

:class:`~trackingbox.fmu.ModelExchangeStepper` integrates with fmpy's
``CVodeSolver``, whose right-hand side is a ctypes callback: every derivative
evaluation (several per solver step, one more per state for each
difference-quotient Jacobian) runs Python. :class:`NativeStepper` is the same
stepper (same public API, counters, errors) whose integration is done by a
small C library, ``stepper.c`` beside this file:

* it owns one CVODE instance from the *same* SUNDIALS libraries fmpy loaded
  (their symbols looked up on fmpy's own library handles), with fmpy's
  settings: BDF, dense direct solver with the difference-quotient Jacobian,
  ``rtol``, ``atol = rtol * nominal`` per state, the same largest step and step
  budget, and ``CVodeSetStopTime`` at every target when the stepper carries
  changes (:meth:`~trackingbox.fmu.ModelExchangeStepper.carry`);
* its right-hand side calls the FMU binary fmpy loaded (``dlsym`` on fmpy's
  handle, fmpy's instance pointer) in fmpy's order (time, inputs, states,
  derivatives) and interpolates the input table in C with the formula
  :meth:`~trackingbox.fmu.Stepper._input_values` uses.

Between steps, a change of Real tunable parameters and/or inputs (:meth:`NativeStepper.set`)
runs the Python path's sequence in C call for call (event mode when a parameter
changes, the values, the event iteration, continuous-time mode, then carry or
re-initialise CVODE); continuous states and Real values are read with one C
call each. :meth:`NativeStepper.advance` does a set, a step and both reads
in one C call (``tbn_advance``: the same FMU and CVODE calls in the same
order), which the tracking runtime's twins use for every step and sub-step.
Python still initialises the FMU through fmpy, runs event iterations after a
step event, and takes other variable types through fmpy.
With the same arithmetic in the same order, a native run reproduces the Python
path's trajectory (bit for bit on the bench twins; the tests bound the
difference by the integrator's tolerance). :func:`cpu_seconds` is the CPU
spent inside the C calls, what the integrator alone costs in a run.

The library is built once per source version with the machine's C compiler
(``$CC``, default ``gcc``) into a per-user cache (``$XDG_CACHE_HOME`` or
``~/.cache``, then ``trackingbox/native/stepper-<hash>.so``) and loaded with
ctypes. :func:`native_reason` says why a model cannot have it: not Linux, not
FMI 3, co-simulation, event indicators, no continuous states, no compiler or a
failed build; :meth:`FMUModel.stepper <trackingbox.fmu.FMUModel.stepper>` also
takes the Python path when ``TRACKINGBOX_NATIVE=0``.
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import logging
import math
import os
import shutil
import subprocess
import sys
import weakref
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
import numpy.typing as npt
import pandas as pd

from ..errors import FMUError, SimulationError
from ..fmu import ModelExchangeStepper, _fmu_calls, _simulation_failure

if TYPE_CHECKING:
    from ..fmu import FMUModel, _FMI

__all__ = ["NativeStepper", "native_reason", "library", "cpu_seconds", "SOURCE", "ENV"]

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("stepper.c")
#: environment variable: ``0`` makes ``FMUModel.stepper(native=None)`` take the Python path
ENV = "TRACKINGBOX_NATIVE"
#: compiler flags (part of the cache key); no floating-point contraction, so the C arithmetic is Python's
CFLAGS = ("-O2", "-shared", "-fPIC", "-ffp-contract=off")

# tbn_step's codes (stepper.c)
_OK, _STEP_EVENT, _TERMINATE, _NONFINITE, _FMU_FAILED, _CVODE_FAILED = 0, 1, 2, 3, -1, -2
# tbn_advance's own codes and flags (stepper.c)
_NO_SET, _SET_FAILED, _AFTER_SET, _READ_FAILED = -100, 10, 11, 12
_EVENT, _CARRY, _EXACT = 1, 2, 4


#: the layouts of a PI controller's and a state compensator's state in tbn_track_rows (stepper.c)
PI_FIELDS = ("u", "e_mem", "has_mem", "e_last", "has_last", "hold_last", "gain", "ti", "te", "span", "p_min",
             "p_max", "mode_hold")
SC_FIELDS = ("m", "e_mem", "has_mem", "e_last", "has_last", "hold_last", "gain", "ts", "te", "mode_hold")
#: tbn_track_rows's outcomes: it reached the batch's end; the next row needs Python; a twin's advance
#: inside the row it wrote last did not end normally
ROWS_STOPPED, ROWS_PYTHON, ROWS_INTERRUPTED = 0, 1, 2

_pd, _pu32, _pint = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_uint32), ctypes.POINTER(ctypes.c_int)


class TwinIO(ctypes.Structure):
    """``tbn_twin_io`` of stepper.c: one twin a batch of tracking rows steps."""

    _fields_ = [("h", ctypes.c_void_p), ("nv", ctypes.c_size_t), ("vr", _pu32), ("is_param", _pint),
                ("applied", _pd), ("given", _pd), ("given_ok", _pint), ("ever_set", _pint), ("limit", _pd),
                ("carry_any", ctypes.c_int), ("extrap", _pint), ("lo", _pd), ("hi", _pd),
                ("force_restart", ctypes.c_int), ("exact", ctypes.c_int), ("time", ctypes.c_double),
                ("carried", ctypes.c_long), ("restarts", ctypes.c_long), ("seconds", ctypes.c_double),
                ("y", _pd), ("out", _pd), ("val", _pd), ("sub", _pd), ("sub_vr", _pu32),
                ("sub_idx", ctypes.POINTER(ctypes.c_size_t))]


class TrackBatch(ctypes.Structure):
    """``tbn_batch`` of stepper.c: a batch of tracking rows (see ``tbn_track_rows``)."""

    _fields_ = [("grid", _pd), ("k0", ctypes.c_size_t), ("k_stop", ctypes.c_size_t), ("substeps", ctypes.c_int),
                ("ts", ctypes.c_double), ("hold_until", ctypes.c_double), ("recovery_until", ctypes.c_double),
                ("stopped", ctypes.POINTER(ctypes.c_ubyte)), ("hold_k", ctypes.c_int),
                ("last_time", ctypes.c_double), ("has_last_time", ctypes.c_int),
                ("npairs", ctypes.c_size_t), ("pi", _pd), ("psamples", ctypes.POINTER(_pd)),
                ("pidx", ctypes.POINTER(ctypes.c_size_t)), ("missing", _pint),
                ("nstates", ctypes.c_size_t), ("comp_t", _pd), ("comp_u", _pd), ("ssamples", ctypes.POINTER(_pd)),
                ("sidx", ctypes.POINTER(ctypes.c_size_t)),
                ("ntags", ctypes.c_size_t), ("tidx", ctypes.POINTER(ctypes.c_size_t)),
                ("tsamples", ctypes.POINTER(_pd)), ("scored", ctypes.POINTER(ctypes.POINTER(ctypes.c_ubyte))),
                ("fits", _pd), ("pstats", _pd), ("cstats", _pd), ("sstats", _pd), ("nread", ctypes.c_size_t),
                ("tw", TwinIO * 2), ("rows", _pd), ("ncols", ctypes.c_size_t), ("cap", ctypes.c_size_t),
                ("done", ctypes.c_size_t), ("status", ctypes.c_int), ("which", ctypes.c_int), ("sub", ctypes.c_int),
                ("code", ctypes.c_int)]


class NativeUnavailable(Exception):
    """Internal: the native library cannot be had here (the message says why)."""


def _compiler() -> str:
    return os.environ.get("CC", "gcc")


def cache_dir() -> Path:
    """Where built libraries are kept: ``$XDG_CACHE_HOME/trackingbox/native`` (default ``~/.cache``)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "trackingbox" / "native"


def library_path() -> Path:
    """The cache path of the library for the current source, compiler and flags."""
    key = hashlib.sha256(SOURCE.read_bytes() + repr((_compiler(), CFLAGS)).encode()).hexdigest()[:16]
    return cache_dir() / f"stepper-{key}.so"


def _build(path: Path) -> None:
    cc = _compiler()
    if shutil.which(cc) is None:
        raise NativeUnavailable(f"no C compiler ({cc!r} not on PATH) to build {SOURCE.name}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise NativeUnavailable(f"cannot create the cache directory {path.parent}: {exc}") from None
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    cmd = [cc, *CFLAGS, "-o", str(tmp), str(SOURCE), "-ldl", "-lm"]
    log.debug("building the native stepper: %s", " ".join(cmd))
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise NativeUnavailable(f"building {SOURCE.name} with {cc} failed: {exc}") from None
    if proc.returncode != 0:
        tmp.unlink(missing_ok=True)
        raise NativeUnavailable(f"building {SOURCE.name} with {cc} failed: {proc.stderr.strip()[:500]}")
    tmp.replace(path)  # atomic: a concurrent build leaves one whole library


#: the libraries this process has loaded (:func:`fmi_call` reads them; it never loads one). Usually one;
#: another cache directory (``XDG_CACHE_HOME``) or compiler in the same process loads a second
_LOADED_LIBS: list[ctypes.CDLL] = []


@functools.lru_cache(maxsize=None)
def _load(path: Path) -> ctypes.CDLL:
    if not path.exists():
        _build(path)
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as exc:
        raise NativeUnavailable(f"loading {path} failed: {exc}") from None
    c_double, c_int, c_size_t, c_void_p, c_long = (ctypes.c_double, ctypes.c_int, ctypes.c_size_t,
                                                   ctypes.c_void_p, ctypes.c_long)
    lib.tbn_new.argtypes = [ctypes.POINTER(c_void_p), c_void_p, c_void_p, c_size_t, c_double, c_double, c_double,
                            c_long, c_int, ctypes.c_char_p, c_size_t]
    lib.tbn_new.restype = c_void_p
    lib.tbn_free.argtypes = [c_void_p]
    lib.tbn_free.restype = None
    lib.tbn_set_inputs.argtypes = [c_void_p, c_size_t, ctypes.POINTER(ctypes.c_uint32), c_size_t,
                                   ctypes.POINTER(c_double), ctypes.POINTER(c_double)]
    lib.tbn_set_inputs.restype = c_int
    lib.tbn_reset.argtypes = [c_void_p, c_double]
    lib.tbn_reset.restype = c_int
    lib.tbn_internal_time.argtypes = [c_void_p]
    lib.tbn_internal_time.restype = c_double
    lib.tbn_step.argtypes = [c_void_p, c_double, c_int, ctypes.POINTER(c_double)]
    lib.tbn_step.restype = c_int
    lib.tbn_error.argtypes = [c_void_p]
    lib.tbn_error.restype = ctypes.c_char_p
    lib.tbn_failed_call.argtypes = [c_void_p, ctypes.POINTER(c_int)]
    lib.tbn_failed_call.restype = ctypes.c_char_p
    lib.tbn_set_parameters.argtypes = [c_void_p, c_size_t, ctypes.POINTER(ctypes.c_uint32), ctypes.POINTER(c_double),
                                       c_int, c_int, c_double, ctypes.POINTER(c_int), ctypes.POINTER(c_double)]
    lib.tbn_set_parameters.restype = c_int
    lib.tbn_get_states.argtypes = [c_void_p, ctypes.POINTER(c_double)]
    lib.tbn_get_states.restype = c_int
    lib.tbn_cpu_seconds.argtypes = []
    lib.tbn_cpu_seconds.restype = c_double
    lib.tbn_rhs_evaluations.argtypes = []
    lib.tbn_rhs_evaluations.restype = ctypes.c_long
    lib.tbn_keep_jacobian.argtypes = [c_void_p, c_int]
    lib.tbn_keep_jacobian.restype = c_int
    lib.tbn_jacobians.argtypes = [c_void_p, ctypes.POINTER(c_long), ctypes.POINTER(c_long)]
    lib.tbn_jacobians.restype = None
    lib.tbn_forget_jacobian.argtypes = [c_void_p]
    lib.tbn_forget_jacobian.restype = None
    lib.tbn_stats.argtypes = [c_void_p, ctypes.POINTER(c_long), ctypes.POINTER(c_long)]
    lib.tbn_stats.restype = None
    pd_, pu32, pint = ctypes.POINTER(c_double), ctypes.POINTER(ctypes.c_uint32), ctypes.POINTER(c_int)
    lib.tbn_advance_reads.argtypes = [c_void_p, c_size_t, pu32, pd_, pd_, pint, pint, pd_, pd_]
    lib.tbn_advance_reads.restype = None
    lib.tbn_advance.argtypes = [c_void_p, c_size_t, pu32, pd_, c_int, c_double, c_double]
    lib.tbn_advance.restype = c_int
    lib.tbn_pi_linear.argtypes = [pd_, c_double, c_double, c_int, c_double]
    lib.tbn_pi_linear.restype = c_double
    lib.tbn_comp_linear.argtypes = [pd_, c_double, c_double, c_int]
    lib.tbn_comp_linear.restype = c_double
    lib.tbn_track_rows.argtypes = [ctypes.POINTER(TrackBatch)]
    lib.tbn_track_rows.restype = c_int
    lib.tbn_closed_new.argtypes = [c_void_p, c_size_t, c_size_t, pu32, pu32, pd_, c_double, c_long, ctypes.c_char_p,
                                   c_size_t]
    lib.tbn_closed_new.restype = c_void_p
    lib.tbn_closed_free.argtypes = [c_void_p]
    lib.tbn_closed_free.restype = None
    lib.tbn_closed_rows.argtypes = [ctypes.POINTER(TrackBatch), c_size_t, c_void_p, c_void_p]
    lib.tbn_closed_rows.restype = c_int
    lib.tbn_closed_stats.argtypes = [c_void_p, ctypes.POINTER(c_long), ctypes.POINTER(c_long)]
    lib.tbn_closed_stats.restype = None
    lib.tbn_fmi_call.argtypes = [ctypes.POINTER(ctypes.c_ulong), ctypes.POINTER(ctypes.c_char_p)]
    lib.tbn_fmi_call.restype = None
    _LOADED_LIBS.append(lib)
    return lib


def library() -> ctypes.CDLL:
    """The native library, built on first use (:class:`NativeUnavailable` says why it cannot be)."""
    if not sys.platform.startswith("linux"):
        raise NativeUnavailable(f"the native stepper is built for Linux only (this is {sys.platform})")
    return _load(library_path())


@functools.lru_cache(maxsize=None)
def _row_formatter() -> tuple[Any, int, int] | None:
    """``tbn_format_rows`` (called holding the GIL), Python's float repr and ``PyMem_Free``; None if not to be had."""
    try:
        library()
        fn = ctypes.PyDLL(str(library_path())).tbn_format_rows
        repr_fn = ctypes.cast(ctypes.pythonapi.PyOS_double_to_string, ctypes.c_void_p).value
        free_fn = ctypes.cast(ctypes.pythonapi.PyMem_Free, ctypes.c_void_p).value
    except (NativeUnavailable, OSError, AttributeError) as exc:
        log.debug("rows are formatted by the csv module: %s", exc)
        return None
    if not repr_fn or not free_fn:
        return None
    fn.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.c_size_t, ctypes.c_size_t, ctypes.c_size_t,
                   ctypes.c_char_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_void_p]
    fn.restype = ctypes.c_long
    return fn, repr_fn, free_fn


def format_rows(rows: npt.NDArray[np.float64], modes: int) -> str | None:
    """*rows* as ``csv.writer(...).writerows`` writes them, the last *modes* columns as "hold"/"auto"; None: not here.

    Every value is written with Python's own float repr (``PyOS_double_to_string``,
    what ``float.__repr__`` and so the csv module use), called from C
    (``tbn_format_rows``), so the text is the csv module's, byte for byte.
    """
    fmt = _row_formatter()
    if fmt is None:
        return None
    fn, repr_fn, free_fn = fmt
    rows = np.ascontiguousarray(rows, dtype=float)
    n, ncols = rows.shape
    cap = n * (ncols * 32 + 2) + 1
    buf = ctypes.create_string_buffer(cap)
    got = fn(rows.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), n, ncols, modes, buf, cap, repr_fn, free_fn)
    if got < 0:
        return None
    return buf.raw[:got].decode("ascii")


def cpu_seconds() -> float:
    """CPU seconds this process spent inside native steps and parameter sets (integration and FMU calls).

    What the integrator alone cost in a run that used :class:`NativeStepper`
    (the difference of two readings): the benchmarks print it beside the run's
    own CPU time. 0.0 where the library is not loaded.
    """
    lib = _loaded()
    return 0.0 if lib is None else float(lib.tbn_cpu_seconds())


def _loaded() -> Any:
    """The native library if this process has loaded it (else None: nothing to read)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        path = library_path()
    except OSError:
        return None
    if _load.cache_info().currsize == 0 or not path.exists():
        return None
    return _load(path)


def fmi_call() -> tuple[int, str] | None:
    """``(seq, name)`` of the native library's calls into FMUs, None where this process has loaded none.

    *seq* (summed over every library loaded here) is odd while one of the
    calls runs and moves on with each; *name* is the FMI function of the one
    running, else of a latest (``"fmi3GetContinuousStateDerivatives"``).
    :class:`trackingbox.supervise.Watchdog` reads it from its own thread: the
    FMU calls made from C (the steppers, the rows in C) have no fmpy frame on
    the Python stack for it to see.
    """
    if not _LOADED_LIBS:
        return None
    total, current = 0, ""
    seq, name = ctypes.c_ulong(), ctypes.c_char_p()
    for lib in list(_LOADED_LIBS):  # the sum: odd while a call of any of them runs (one thread steps)
        lib.tbn_fmi_call(ctypes.byref(seq), ctypes.byref(name))
        total += int(seq.value)
        if seq.value % 2 or not current:
            current = (name.value or b"").decode("ascii", "replace")
    return total, current


def rhs_evaluations() -> int:
    """Right-hand-side evaluations this process's native integrations made (CVODE's steps, Newton
    iterations and difference-quotient Jacobians; both steppers and the closed-loop integrators).

    The integrator's work counted in FMU derivative calls, steadier than :func:`cpu_seconds` on a
    loaded machine (the difference of two readings); 0 where the library is not loaded.
    """
    lib = _loaded()
    return 0 if lib is None else int(lib.tbn_rhs_evaluations())


def native_reason(model: FMUModel) -> str | None:
    """Why *model* cannot run with :class:`NativeStepper`, or None if it can (builds the library if needed).

    The environment variable ``TRACKINGBOX_NATIVE=0`` is *not* looked at here
    (:meth:`~trackingbox.fmu.FMUModel.stepper` does, for its automatic choice).
    """
    name = model.path.name
    md = model.info.model_description
    if model.interface != "ModelExchange":
        return f"{name} runs as co-simulation"
    if not model.info.fmi_version.startswith("3"):
        return f"{name} is FMI {model.info.fmi_version}; the native stepper drives FMI 3 only"
    assert md is not None
    if int(md.numberOfEventIndicators or 0) > 0:
        return f"{name} has {md.numberOfEventIndicators} event indicators (state events)"
    if int(md.numberOfContinuousStates or 0) == 0:
        return f"{name} has no continuous states"
    try:
        library()
    except NativeUnavailable as exc:
        return str(exc)
    return None


class _Solver:
    """What :class:`~trackingbox.fmu.ModelExchangeStepper` asks of its solver, on the native CVODE."""

    def __init__(self, lib: ctypes.CDLL, handle: int) -> None:
        self.lib = lib
        self.handle = handle
        #: stop exactly at each target time (carry mode)
        self.exact = False

    def reset(self, time: float) -> None:
        code = self.lib.tbn_reset(self.handle, time)
        if code != _OK:
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
    from fmpy.fmi1 import FMICallException

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

    def __init__(self, model: FMUModel, fmi: _FMI, *, start_time: float, parameters: dict[str, Any],
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
        from fmpy.sundials import libraries as sl

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
                                          nom.ctypes.data_as(_pd), max_step, 100000, err, len(err))
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
        if code == _CVODE_FAILED:
            raise _simulation_failure(f"solver failed in {name} between t = {self.time:g} s and "
                                      f"t = {target:g} s", _failure_text(self._lib, self._handle),
                                      self.model.log_messages, solver=True) from None
        self.time = float(self._reached.value)
        if code == _FMU_FAILED:
            raise _simulation_failure(f"simulation of {name} failed at t = {self.time:g} s",
                                      _failure_text(self._lib, self._handle), self.model.log_messages)
        if code == _TERMINATE:
            raise SimulationError(f"{name} requested termination at t = {self.time:g} s")
        time_event = self._next_event is not None and math.isclose(self.time, self._next_event)
        if code == _STEP_EVENT or time_event:
            with _fmu_calls(f"simulation of {name} failed at t = {self.time:g} s", self.model.log_messages):
                self._event_iteration()
                self._solver.reset(self.time)
            self._check_states()
        elif code == _NONFINITE:
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
            raise _simulation_failure(f"setting {', '.join(changed)} in {name} at t = {self.time:g} s failed",
                                      _failure_text(self._lib, self._handle), self.model.log_messages)
        if code == _TERMINATE:
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
            code = self._lib.tbn_advance(self._handle, 0, None, None, _EXACT if exact else 0, self.time, t_next)
        else:
            changed, plan = planned
            if plan.inputs and self._in_names:
                self._drop_inputs(set(plan.inputs))  # an input set here is no longer driven by the table
            plan.buffer[:] = list(changed.values())
            flags = (_EVENT if plan.parameters else 0) | (_CARRY if exact and not restart else 0) | \
                (_EXACT if exact else 0)
            code = self._lib.tbn_advance(self._handle, plan.n, plan.vr, plan.pointer, flags, self.time, t_next)
        return self._advance_end(code, planned, t_next, names, rplan)

    def _advance_end(self, code: int, planned: tuple[dict[str, Any], Any] | None, t_next: float,
                     names: tuple[str, ...], rplan: tuple[int, npt.NDArray[np.float64]]
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """What :meth:`advance` does after its ``tbn_advance`` call returned *code*."""
        if planned is not None:
            self._after_set(self._set_code.value, *planned)  # raises when the set failed
        if code == _OK:
            self.time = t_next
            return self._x[: self._nx].copy(), rplan[1][: rplan[0]].copy()
        if code == _READ_FAILED:
            self.time = t_next
            status = ctypes.c_int(0)
            call = self._lib.tbn_failed_call(self._handle, ctypes.byref(status))
            raise _fmi_exception(call.decode(), status.value)
        if code == _AFTER_SET:
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
        if self._lib.tbn_get_states(self._handle, self._px) != _OK:
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
            if code != _OK:
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
