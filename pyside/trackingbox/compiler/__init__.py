"""Modelica source → FMU.

``compile_model(source, model, backend=...)`` is the one entry point. Two
backends return the same :class:`CompileResult`:

* ``openmodelica``: OMPython drives ``omc`` (FMI 2.0); used where omc is installed.
* ``embedded``: rumoca + CasADi + the C compiler (FMI 3.0 model exchange); needs
  only PyPI packages. ``auto`` picks openmodelica when ``omc`` is on PATH, else
  embedded.
"""
from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from ..errors import CompileError, TrackingError
from .openmodelica import omc_available
from .source import resolve_source

log = logging.getLogger(__name__)

class InternalCompileError(CompileError):
    """A backend failed with an unexpected exception (a bug of trackingbox, not of the model):
    reported as a clean error naming the model and the exception instead of a traceback."""


Backend = Literal["auto", "embedded", "openmodelica"]
BACKENDS = ("auto", "embedded", "openmodelica")


@dataclass(frozen=True)
class CompileResult:
    """What a compilation produced."""

    fmu: Path
    backend: str
    fmi_version: str
    seconds: float
    states: int
    parameters: int
    log: str

    def to_json(self) -> dict:
        return {
            "fmu": str(self.fmu),
            "backend": self.backend,
            "fmi_version": self.fmi_version,
            "seconds": round(self.seconds, 3),
            "states": self.states,
            "parameters": self.parameters,
        }


def library_path() -> Path:
    """The shipped Modelica library ``TrackingBox`` (a package directory)."""
    return Path(str(resources.files("trackingbox.modelica"))) / "TrackingBox"


def choose_backend(backend: str) -> str:
    """The backend *backend* names; ``auto`` is ``openmodelica`` when ``omc`` is on PATH (or under
    ``$OPENMODELICAHOME/bin``), else ``embedded``. The choice is logged (INFO)."""
    if backend not in BACKENDS:
        raise CompileError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if backend == "auto":
        chosen = "openmodelica" if omc_available() else "embedded"
        log.info("backend auto: %s (%s)", chosen, "omc found" if chosen == "openmodelica" else "no omc on PATH")
        return chosen
    return backend


def compile_model(
    source: str | Path,
    model: str,
    *,
    backend: str = "auto",
    output: str | Path | None = None,
    libraries: tuple[str | Path, ...] | list[str | Path] = (),
    expected: Any = None,
    parameters: str = "tunable",
) -> CompileResult:
    """Compile the Modelica class *model* from *source* into an FMU.

    Parameters
    ----------
    source:
        A ``.mo`` file or a Modelica package directory (with ``package.mo``).
    model:
        Full class name, e.g. ``"TrackingBox.Benches.HeatExchanger.Twin"``.
    backend:
        ``"auto"``, ``"embedded"`` or ``"openmodelica"``.
    output:
        Where to write the FMU (default: ``<last name of model>.fmu`` in the
        current directory). Written atomically: a failed compilation leaves
        no file behind.
    libraries:
        Further package directories the source uses (e.g. the shipped
        library when compiling generated code that lives elsewhere).
    expected:
        An :class:`~trackingbox.compiler.omc_interface.ExpectedInterface`
        (e.g. ``ExpectedInterface.from_spec(spec)``): after the build, the FMU
        must expose these parameters (tunable), inputs and outputs under these
        names, whichever backend built it; otherwise a :class:`CompileError`
        names each difference and no FMU is left behind.
    parameters:
        ``"tunable"`` (default): the embedded backend exports every parameter
        tunable. ``"fixed"``: it declares them with FMI variability ``fixed``
        (set only before initialisation), as Dymola and OpenModelica export
        most parameters: an FMU to try the fixed-parameter path on. The
        OpenModelica backend decides per parameter itself and takes only the
        default.

    Raises
    ------
    CompileError
        The source does not exist, does not parse (file and line named), the
        class is unknown, or the model is not compilable.
    UnsupportedConstructError
        The embedded backend met a construct it does not support.
    """
    chosen = choose_backend(backend)
    if parameters not in ("tunable", "fixed"):
        raise CompileError(f"parameters must be 'tunable' or 'fixed', not {parameters!r}")
    if parameters == "fixed" and chosen != "embedded":
        raise CompileError("--parameters fixed is an option of the embedded backend (OpenModelica decides each "
                           "parameter's variability itself): add --backend embedded")
    src = resolve_source(source)
    out = Path(output) if output is not None else Path.cwd() / f"{model.rsplit('.', 1)[-1]}.fmu"
    out = out.resolve()
    libs = tuple(Path(p).resolve() for p in libraries)
    t0 = time.perf_counter()
    try:
        if chosen == "embedded":
            from .embedded import compile_embedded

            text, states, params = compile_embedded(src, model, out, libs, parameters)
            version = "3.0"
        else:
            from .openmodelica import compile_openmodelica

            text, states, params = compile_openmodelica(src, model, out, libs, expected=expected)
            version = "2.0"
    except TrackingError:
        raise
    except RecursionError:  # before RuntimeError, its base class
        raise CompileError(f"{model!r} from {src.entry} nests expressions or function calls too deeply for "
                           f"the {chosen} backend's translation (Python's recursion limit, "
                           f"{sys.getrecursionlimit()}): split the expression") from None
    except RuntimeError as exc:  # CasADi and friends: never a traceback for a model problem
        raise CompileError(f"{chosen} backend failed on {model!r}: {str(exc).strip()[:2000]}") from None
    except Exception as exc:  # noqa: BLE001 - a bug of ours: a clean error, the traceback in the debug log
        log.debug("internal error compiling %s", model, exc_info=True)
        raise InternalCompileError(
            f"internal error of the {chosen} backend on {model!r} from {src.entry}: "
            f"{type(exc).__name__}: {str(exc)[:500]} (please report it with the model)") from None
    seconds = time.perf_counter() - t0
    if expected is not None and chosen == "embedded":  # omc's build checks before writing
        from .omc_interface import compare_interface

        report = compare_interface(out, expected)
        if not report.ok:
            out.unlink(missing_ok=True)
            report.raise_for_problems(f"{out.name} (model {model})")
    log.info("compiled %s with %s in %.2f s -> %s", model, chosen, seconds, out)
    return CompileResult(out, chosen, version, seconds, states, params, text)


__all__ = ["BACKENDS", "CompileResult", "InternalCompileError", "compile_model", "library_path", "omc_available"]
