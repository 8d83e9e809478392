"""The native library: CVODE and an FMU's right-hand side in C, built and loaded here.

:class:`~trackingbox.fmu.steppers.ModelExchangeStepper` integrates with fmpy's
``CVodeSolver``, whose right-hand side is a ctypes callback: every derivative
evaluation (several per solver step, one more per state for each
difference-quotient Jacobian) runs Python. The small C library ``stepper.c``
beside this file does that integration with no Python inside a step; the
stepper that drives it is :class:`trackingbox.fmu.native_stepper.NativeStepper`
(this package knows nothing of :mod:`trackingbox.fmu`; the dependency runs one
way, from the FMU layer to here). The library

* owns one CVODE instance from the *same* SUNDIALS libraries fmpy loaded
  (their symbols looked up on fmpy's own library handles), with fmpy's
  settings: BDF, dense direct solver with the difference-quotient Jacobian,
  ``rtol``, ``atol = rtol * nominal`` per state, the same largest step and step
  budget, and ``CVodeSetStopTime`` at every target when the stepper carries
  changes (:meth:`~trackingbox.fmu.steppers.ModelExchangeStepper.carry`);
* calls, in its right-hand side, the FMU binary fmpy loaded (``dlsym`` on fmpy's
  handle, fmpy's instance pointer) in fmpy's order (time, inputs, states,
  derivatives) and interpolates the input table in C with the formula
  :meth:`~trackingbox.fmu.steppers.Stepper._input_values` uses.

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
failed build; :meth:`FMUModel.stepper <trackingbox.fmu.model.FMUModel.stepper>` also
takes the Python path when ``TRACKINGBOX_NATIVE=0``.
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from ..fmu.model import FMUModel

__all__ = ["native_reason", "library", "cpu_seconds", "fmi_call", "rhs_evaluations", "format_rows",
           "NativeUnavailable", "SOURCE", "ENV"]

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("stepper.c")
#: environment variable: ``0`` makes ``FMUModel.stepper(native=None)`` take the Python path
ENV = "TRACKINGBOX_NATIVE"
#: compiler flags (part of the cache key); no floating-point contraction, so the C arithmetic is Python's
CFLAGS = ("-O2", "-shared", "-fPIC", "-ffp-contract=off")

# tbn_step's codes (stepper.c)
OK, STEP_EVENT, TERMINATE, NONFINITE, FMU_FAILED, CVODE_FAILED = 0, 1, 2, 3, -1, -2
# tbn_advance's own codes and flags (stepper.c)
NO_SET, SET_FAILED, AFTER_SET, READ_FAILED = -100, 10, 11, 12
EVENT, CARRY, EXACT = 1, 2, 4


#: the layouts of a PI controller's and a state compensator's state in tbn_track_rows (stepper.c)
PI_FIELDS = ("u", "e_mem", "has_mem", "e_last", "has_last", "hold_last", "gain", "ti", "te", "span", "p_min",
             "p_max", "mode_hold")
SC_FIELDS = ("m", "e_mem", "has_mem", "e_last", "has_last", "hold_last", "gain", "ts", "te", "mode_hold")
#: tbn_track_rows's outcomes: it reached the batch's end; the next row needs Python; a twin's advance
#: inside the row it wrote last did not end normally
ROWS_STOPPED, ROWS_PYTHON, ROWS_INTERRUPTED = 0, 1, 2

PD, PU32, PINT = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_uint32), ctypes.POINTER(ctypes.c_int)


class TwinIO(ctypes.Structure):
    """``tbn_twin_io`` of stepper.c: one twin a batch of tracking rows steps."""

    _fields_ = [("h", ctypes.c_void_p), ("nv", ctypes.c_size_t), ("vr", PU32), ("is_param", PINT),
                ("applied", PD), ("given", PD), ("given_ok", PINT), ("ever_set", PINT), ("limit", PD),
                ("carry_any", ctypes.c_int), ("extrap", PINT), ("lo", PD), ("hi", PD),
                ("force_restart", ctypes.c_int), ("exact", ctypes.c_int), ("time", ctypes.c_double),
                ("carried", ctypes.c_long), ("restarts", ctypes.c_long), ("seconds", ctypes.c_double),
                ("y", PD), ("out", PD), ("val", PD), ("sub", PD), ("sub_vr", PU32),
                ("sub_idx", ctypes.POINTER(ctypes.c_size_t))]


class TrackBatch(ctypes.Structure):
    """``tbn_batch`` of stepper.c: a batch of tracking rows (see ``tbn_track_rows``)."""

    _fields_ = [("grid", PD), ("k0", ctypes.c_size_t), ("k_stop", ctypes.c_size_t), ("substeps", ctypes.c_int),
                ("ts", ctypes.c_double), ("hold_until", ctypes.c_double), ("recovery_until", ctypes.c_double),
                ("stopped", ctypes.POINTER(ctypes.c_ubyte)), ("hold_k", ctypes.c_int),
                ("last_time", ctypes.c_double), ("has_last_time", ctypes.c_int),
                ("npairs", ctypes.c_size_t), ("pi", PD), ("psamples", ctypes.POINTER(PD)),
                ("pidx", ctypes.POINTER(ctypes.c_size_t)), ("missing", PINT),
                ("nstates", ctypes.c_size_t), ("comp_t", PD), ("comp_u", PD), ("ssamples", ctypes.POINTER(PD)),
                ("sidx", ctypes.POINTER(ctypes.c_size_t)),
                ("ntags", ctypes.c_size_t), ("tidx", ctypes.POINTER(ctypes.c_size_t)),
                ("tsamples", ctypes.POINTER(PD)), ("scored", ctypes.POINTER(ctypes.POINTER(ctypes.c_ubyte))),
                ("fits", PD), ("pstats", PD), ("cstats", PD), ("sstats", PD), ("nread", ctypes.c_size_t),
                ("tw", TwinIO * 2), ("rows", PD), ("ncols", ctypes.c_size_t), ("cap", ctypes.c_size_t),
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
