"""The no-Python lower bound printed by the benchmarks (``scripts/bench_*``).

fmpy's ``simulate_fmu`` is not a no-Python run: for model exchange its
``CVodeSolver`` hands CVODE a ctypes callback, so every right-hand-side
evaluation (several per integrator step, plus one per state for each
difference-quotient Jacobian) goes through Python, which is exactly what
trackingbox's ``ModelExchangeStepper`` does too. The bound here is therefore a
small C driver (``_bound_driver.c``, built with gcc on first use into
``.cache/bound``) that integrates the same FMU with the *same* CVODE library
fmpy ships, the same method and settings (BDF, dense DQ Jacobian, rtol,
atol = rtol x nominal, the same largest step, linearly interpolated inputs,
returns on the same output grid where the outputs are read) and no Python
between the solver and the FMU. It is a lower bound for any Python driver of
that FMU with those settings: the numerical work is the same and only the
interpreter's cost per call is gone. (A different integrator or looser
tolerances could be faster still; that would be a different computation.)

The driver reports the CPU and wall time of its integration loop only
(instantiation and initialisation are left out, as the runtime's ``plain``
figure leaves them out) and writes the outputs on the grid, so a benchmark can
check the bound computed the same trajectory as its Python run.
"""
from __future__ import annotations

import hashlib
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SOURCE = Path(__file__).with_name("_bound_driver.c")


@dataclass(frozen=True)
class Bound:
    """One no-Python run: integration-loop CPU and wall seconds, CVODE counters, outputs on the grid."""

    cpu: float
    wall: float
    rhs: int
    steps: int
    outputs: np.ndarray  # (grid, outputs)


def driver() -> Path:
    """The compiled driver (built once per source version under ``.cache/bound``)."""
    digest = hashlib.sha256(SOURCE.read_bytes()).hexdigest()[:12]
    exe = ROOT / ".cache" / "bound" / f"bound_driver-{digest}"
    if not exe.exists():
        exe.parent.mkdir(parents=True, exist_ok=True)
        tmp = exe.with_name(exe.name + ".tmp")
        proc = subprocess.run(["gcc", "-O2", "-o", str(tmp), str(SOURCE), "-ldl"], capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"building {SOURCE.name} failed: {proc.stderr.strip()}")
        tmp.replace(exe)
    return exe


def run_bound(fmu: Path, *, grid: Sequence[float], outputs: Sequence[str],
              parameters: Mapping[str, float] | None = None,
              inputs: "object | None" = None, tolerance: float = 1e-6,
              max_step: float | None = None) -> Bound:
    """Integrate *fmu* over *grid* with no Python in the loop and read *outputs* at each grid time.

    Parameters
    ----------
    fmu : path
        An FMI 3 model-exchange FMU without event indicators (the embedded path's).
    grid : sequence of float
        Output times; the run starts at ``grid[0]``.
    outputs : sequence of str
        Variables read at each grid time.
    parameters : mapping, optional
        Start values set before initialisation.
    inputs : pandas.DataFrame, optional
        ``time`` plus one column per FMU input, interpolated linearly (held beyond the ends).
    tolerance : float
        CVODE's relative tolerance.
    max_step : float, optional
        CVODE's largest step; default the smallest spacing of the input times
        (what ``ModelExchangeStepper`` uses), else unbounded.
    """
    import fmpy
    from fmpy import platform_tuple

    fmu = Path(fmu)
    md = fmpy.read_model_description(str(fmu))
    if md.modelExchange is None or not md.fmiVersion.startswith("3"):
        raise ValueError(f"{fmu}: the bound driver needs an FMI 3 model-exchange FMU")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    grid = np.asarray(grid, dtype=float)
    sundials = Path(fmpy.__file__).parent / "sundials" / platform_tuple
    with tempfile.TemporaryDirectory(prefix="bound-") as tmp:
        unzip = Path(fmpy.extract(str(fmu), unzipdir=str(Path(tmp) / "fmu")))
        binary = unzip / "binaries" / platform_tuple / f"{md.modelExchange.modelIdentifier}.so"
        resources = unzip / "resources"
        lines = [str(sundials), str(binary), md.guid, resources.as_uri() + "/" if resources.is_dir() else "-"]
        if inputs is not None:
            names = [c for c in inputs.columns if c != "time"]
            times = inputs["time"].to_numpy(float)
            table = inputs[names].to_numpy(float)
        else:
            names, times, table = [], np.zeros(0), np.zeros((0, 0))
        if max_step is None:
            max_step = float(np.min(np.diff(times))) if times.size > 1 else float("inf")
        lines.append(" ".join(repr(float(x)) for x in (grid[0], grid[-1], tolerance,
                                                         max_step if np.isfinite(max_step) else 1e300)))
        params = dict(parameters or {})
        lines.append(str(len(params)))
        lines += [f"{vr[n]} {float(v)!r}" for n, v in params.items()]
        lines.append(f"{len(names)} " + " ".join(str(vr[n]) for n in names))
        lines.append(str(times.size))
        lines += [" ".join(repr(float(x)) for x in (t, *row)) for t, row in zip(times, table)]
        lines.append(str(grid.size))
        lines += [repr(float(t)) for t in grid]
        lines.append(f"{len(outputs)} " + " ".join(str(vr[n]) for n in outputs))
        job = Path(tmp) / "job.txt"
        job.write_text("\n".join(lines) + "\n")
        out = Path(tmp) / "out.bin"
        proc = subprocess.run([str(driver()), str(job), str(out)], capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"bound driver failed on {fmu.name} (exit {proc.returncode}): {proc.stderr.strip()}")
        fields = proc.stdout.split()
        values = dict(zip(fields[::2], fields[1::2]))
        data = np.fromfile(out, dtype=float).reshape(grid.size, len(outputs))
    return Bound(cpu=float(values["cpu"]), wall=float(values["wall"]), rhs=int(values["rhs"]),
                 steps=int(values["steps"]), outputs=data)
