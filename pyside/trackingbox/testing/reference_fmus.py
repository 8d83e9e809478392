"""Build the Modelica Association's Reference FMUs from their C sources, for tests and benchmarks.

The sources are in ``../shared/reference-fmus`` beside the repository (a checkout of
https://github.com/modelica/Reference-FMUs; another one can be given as *sources*). They are FMUs written by
another party, with both interfaces (model exchange and co-simulation), and parameters of FMI
variability ``fixed`` (``Dahlquist``'s ``k``, ``VanDerPol``'s ``mu``), as tools such as Dymola and
OpenModelica export them. :func:`build_reference_fmus` builds the named models for FMI 2 or 3 with
CMake and the C compiler (one configure and one build per call, in a folder the caller owns).
"""
from __future__ import annotations

import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path

__all__ = ["default_sources", "build_reference_fmus", "ReferenceBuildError"]


class ReferenceBuildError(RuntimeError):
    """CMake or the compiler failed (the message holds the tail of their output)."""


def default_sources() -> Path:
    """``../shared/reference-fmus`` beside the repository."""
    return Path(__file__).resolve().parents[3].parent / "shared" / "reference-fmus"


def _run(cmd: Sequence[str], cwd: Path, what: str) -> None:
    done = subprocess.run(list(cmd), cwd=cwd, capture_output=True, text=True)
    if done.returncode != 0:
        tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-20:])
        raise ReferenceBuildError(f"{what} failed (exit {done.returncode}) in {cwd}:\n{tail}")


def build_reference_fmus(dest: Path, fmi_version: int, models: Sequence[str] = ("Dahlquist", "VanDerPol"),
                         sources: Path | None = None) -> dict[str, Path]:
    """Build *models* of the Reference FMUs for FMI *fmi_version* (2 or 3) under *dest*.

    Returns model name -> path of its ``.fmu``. Needs ``cmake`` and a C compiler
    on ``PATH``; :class:`FileNotFoundError` names what is missing, and
    :class:`ReferenceBuildError` carries the build's last lines when it fails.
    """
    if fmi_version not in (2, 3):
        raise ValueError(f"FMI version must be 2 or 3, not {fmi_version!r}")
    src = Path(sources) if sources is not None else default_sources()
    if not (src / "CMakeLists.txt").is_file():
        raise FileNotFoundError(f"the Reference FMUs' sources are not at {src} (no CMakeLists.txt)")
    cmake = shutil.which("cmake")
    if cmake is None:
        raise FileNotFoundError("cmake is not on PATH: it builds the Reference FMUs (apt-get install cmake)")
    build = Path(dest) / f"fmi{fmi_version}"
    build.mkdir(parents=True, exist_ok=True)
    _run([cmake, "-S", str(src.resolve()), "-B", str(build), f"-DFMI_VERSION={fmi_version}",
          "-DCMAKE_BUILD_TYPE=Release"], build, "configuring the Reference FMUs with cmake")
    _run([cmake, "--build", str(build), "--target", *models, "--", "-j2"], build,
         f"building the Reference FMUs {', '.join(models)} (FMI {fmi_version})")
    out = {}
    for name in models:
        fmu = build / "fmus" / f"{name}.fmu"
        if not fmu.is_file():
            raise ReferenceBuildError(f"the build of {name} (FMI {fmi_version}) wrote no {fmu}")
        out[name] = fmu
    return out
