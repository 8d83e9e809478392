"""A model whose initialisation needs ``homotopy()``: refused where its FMU cannot initialise.

rumoca 0.10.2 flattens ``homotopy(actual, simplified)`` to ``actual`` (its flat model holds no trace of
``simplified``), so the embedded path solves the initial equations from the start values with the
actual equations only; Modelica tools solve the simplified problem first and continue from it to the
actual one (MLS 3.7.4.4). Where the model's classes call ``homotopy`` and it has an initialisation
problem, the compiled FMU is initialised once at its defaults (in a child process: a failing FMU cannot
take the compiler with it); if that fails, the FMU is deleted and the model refused naming the calls
(``Modelica.Fluid.Examples.HeatingSystem``: from the start values, equal pressures along each pipe, the
steady initial equations give no flow, and Newton's matrix is singular there: the temperatures of an
adiabatic pipe and tank are then undetermined).
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from ..errors import UnsupportedConstructError
from .library import locate
from .source import ModelicaSource

CHECK_TIMEOUT = 300.0
"""Seconds the child process may take to initialise the FMU (an IF97 model's initial solve included)."""

_CHILD = r"""
import json, sys
import fmpy
from fmpy.fmi3 import FMU3Model
path = sys.argv[1]
md = fmpy.read_model_description(path)
unzipped = fmpy.extract(path)
errors = []
def log(*args):
    if int(args[-3]) >= 3:
        m = args[-1]
        errors.append(m.decode(errors="replace") if isinstance(m, bytes) else str(m))
fmu = FMU3Model(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.modelExchange.modelIdentifier,
                instanceName="init_check")
fmu.instantiate(loggingOn=True, logMessage=log)
exp = md.defaultExperiment
start = float(exp.startTime) if exp is not None and exp.startTime is not None else 0.0
failed = ""
try:
    fmu.enterInitializationMode(startTime=start)
    fmu.exitInitializationMode()
except Exception as exc:
    failed = errors[-1] if errors else str(exc)
print(json.dumps({"failed": failed}))
"""


def initialisation_failure(fmu: Path) -> str:
    """The FMU's error message when it leaves initialisation mode at its defaults; "" where it initialises
    (or where the check itself cannot run: the FMU is then kept, as before the check)."""
    try:
        done = subprocess.run([sys.executable, "-c", _CHILD, str(fmu)], capture_output=True, text=True,
                              timeout=CHECK_TIMEOUT)
        return str(json.loads(done.stdout.strip().splitlines()[-1])["failed"])
    except (subprocess.TimeoutExpired, OSError, ValueError, IndexError, KeyError):
        return ""


def refuse_failed_homotopy_start(source: ModelicaSource, model: str, libraries: tuple[Path, ...],
                                 fmu: Path) -> None:
    """Raise :class:`UnsupportedConstructError` (and delete *fmu*) where the classes *model* uses call
    ``homotopy`` and the FMU does not initialise at its defaults; else nothing."""
    calls = locate(source, model, r"(?<![\w.])homotopy\s*\(", limit=4, libraries=libraries)
    if not calls:
        return
    failed = initialisation_failure(fmu)
    if not failed:
        return
    fmu.unlink(missing_ok=True)
    raise UnsupportedConstructError(
        f"unsupported Modelica construct in {model}: homotopy(actual, simplified) at "
        f"{', '.join(str(c) for c in calls)}{' ...' if len(calls) >= 4 else ''}: rumoca 0.10.2 keeps only the "
        f"actual argument (Modelica tools start the initialisation from the simplified one), and from the "
        f"start values the actual initial equations are not solved (the FMU, at its default parameters: "
        f"{failed}). "
        "The embedded backend cannot compile it; use --backend openmodelica where omc is installed, or "
        "give start values near the initial solution")
