"""The OpenModelica backend: OMPython drives ``omc`` to build an FMI 2.0 FMU.

Used where ``omc`` is on PATH (OpenModelica's own installers; it is not in
Debian's or PyPI's packages).
"""
from __future__ import annotations

import logging
import os
import shutil
import tempfile
from pathlib import Path

from ..errors import CompileError
from .source import ModelicaSource

log = logging.getLogger(__name__)


def omc_available() -> bool:
    """True when an ``omc`` executable is on PATH (or named by ``OPENMODELICAHOME``)."""
    if shutil.which("omc"):
        return True
    home = os.environ.get("OPENMODELICAHOME")
    return bool(home and (Path(home) / "bin" / "omc").exists())


def _call(omc, expr: str, what: str):
    log.debug("omc: %s", expr)
    result = omc.sendExpression(expr)
    if result is False or result is None or result == "":
        errors = omc.sendExpression("getErrorString()")
        raise CompileError(f"OpenModelica failed to {what}: {str(errors).strip() or 'no message'}")
    return result


def compile_openmodelica(source: ModelicaSource, model: str, output: Path,
                         libraries: tuple[Path, ...] = ()) -> tuple[str, int, int]:
    """Compile with omc through OMPython; returns (log, n_states, n_parameters)."""
    if not omc_available():
        raise CompileError("the openmodelica backend needs omc on PATH; it is not installed here "
                           "(use --backend embedded)")
    try:
        from OMPython import OMCSessionZMQ
    except ImportError as exc:  # pragma: no cover - OMPython is a dependency
        raise CompileError(f"OMPython is not importable: {exc}") from None
    omc = OMCSessionZMQ()
    logs: list[str] = []
    with tempfile.TemporaryDirectory(prefix="tbx-omc-") as tmp:
        try:
            _call(omc, f'cd("{Path(tmp).as_posix()}")', "change directory")
            for lib in libraries:
                _call(omc, f'loadFile("{(Path(lib) / "package.mo").as_posix() if Path(lib).is_dir() else Path(lib).as_posix()}")',
                      f"load {lib}")
            _call(omc, f'loadFile("{source.entry.as_posix()}")', f"load {source.entry}")
            fmu = _call(omc, f'buildModelFMU({model}, version="2.0", fmuType="me_cs")', f"build an FMU of {model}")
            logs.append(str(omc.sendExpression("getErrorString()")))
            built = Path(str(fmu))
            if not built.is_file():
                raise CompileError(f"OpenModelica reported {built} but no FMU was written")
            output.parent.mkdir(parents=True, exist_ok=True)
            part = output.with_name(f".{output.name}.part")
            shutil.copyfile(built, part)
            os.replace(part, output)
        finally:
            try:
                omc.sendExpression("quit()")
            except Exception:  # noqa: BLE001 - session teardown
                pass
    from fmpy import read_model_description

    md = read_model_description(str(output))
    states = len(md.derivatives)
    params = sum(1 for v in md.modelVariables if v.causality == "parameter" and v.type in ("Real", "Float64"))
    return "\n".join(logs), states, params
