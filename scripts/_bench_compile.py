#!/usr/bin/env python3
"""Benchmark: compile time per bench validation model, and simulation speed of its FMU three ways.

* ours: the FMU through fmpy's ``simulate_fmu`` (CVODE, a Python right-hand
  side: what estimation and tracking pay), instance reused over repeated runs;
* peer: rumoca's own native simulation of the same Modelica model;
* bound: the same FMU integrated by the C driver of ``scripts/_bound.py`` with
  the settings ``simulate_fmu`` uses (CVODE BDF, rtol 1e-6, largest step
  stop/50, the same 500-interval output grid), no Python in the loop.

Speeds are simulated seconds per wall second and per CPU second (the machine
may be shared: CPU seconds are the steadier figure). This is a benchmark, not
a test.

Then the 7-effect evaporator train (``Benches.EvaporatorTrain.Benchmarks``):
compile seconds and one simulated day through ``FMUModel`` at a 10 s output
grid, wall and CPU seconds (the front end and gcc run in child processes: their
CPU is counted); the issue's targets are 60 s each. ``--train`` runs only that.
"""
from __future__ import annotations

import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import fmpy  # noqa: E402
import rumoca  # noqa: E402
from _bound import run_bound  # noqa: E402

from trackingbox.compiler import compile_model, library_path  # noqa: E402

RUNS = 5


def timed(fn) -> tuple[float, float]:
    """Wall and CPU seconds of RUNS calls of *fn*."""
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in range(RUNS):
        fn()
    return time.perf_counter() - w0, time.process_time() - c0


def cpu_with_children() -> float:
    """CPU seconds of this process and its waited-for children."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def train() -> None:
    """Compile and one simulated day of the 7-effect evaporator train's plant and twin."""
    from trackingbox.fmu import FMUModel

    lib = library_path()
    print()
    print(f"{'7-effect train (target 60 s each)':56s} {'compile s':>9s} {'CPU s':>7s} {'1 day s':>8s} "
          f"{'CPU s':>7s} {'states':>6s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("PlantDay", "TwinDay"):
            model = f"TrackingBox.Benches.EvaporatorTrain.Benchmarks.{name}"
            t0, c0 = time.perf_counter(), cpu_with_children()
            res = compile_model(lib, model, backend="embedded", output=Path(tmp) / f"{name}.fmu")
            t_compile, c_compile = time.perf_counter() - t0, cpu_with_children() - c0
            with FMUModel(res.fmu, tolerance=1e-6) as fmu:
                t0, c0 = time.perf_counter(), cpu_with_children()
                fmu.simulate(stop_time=86400.0, output_interval=10.0,
                             outputs=["bench.FI_product", "bench.DI_product"])
                t_day, c_day = time.perf_counter() - t0, cpu_with_children() - c0
            print(f"{model.removeprefix('TrackingBox.Benches.'):56s} {t_compile:9.1f} {c_compile:7.1f} "
                  f"{t_day:8.1f} {c_day:7.1f} {res.states:6d}")
    print("(one day at a 10 s output grid, CVode tolerance 1e-6, FMU extracted and instantiated once; one run)")


def main() -> int:
    if "--train" in sys.argv[1:]:
        train()
        return 0
    lib = library_path()
    models = []
    for bench in sorted(p for p in (lib / "Benches").iterdir() if p.is_dir()):
        val = bench / "Validation"
        if val.is_dir():
            models += [f"TrackingBox.Benches.{bench.name}.Validation.{f.stem}"
                       for f in sorted(val.glob("*.mo")) if f.name != "package.mo"]
    print("compile: embedded path. simulation, simulated s per wall s / per CPU s: ours = the FMU through fmpy "
          "(Python RHS), peer = rumoca's native simulation, bound = the FMU with no Python in the loop")
    print(f"{'model':56s} {'compile s':>9s} {'ours wall':>10s} {'ours CPU':>10s} {'peer wall':>10s} "
          f"{'peer CPU':>10s} {'bound wall':>10s} {'bound CPU':>10s} {'ours/peer':>9s} {'bound/ours':>10s} "
          f"{'check':>8s}")
    with tempfile.TemporaryDirectory() as tmp:
        for model in models:
            t0 = time.perf_counter()
            res = compile_model(lib, model, backend="embedded", output=Path(tmp) / f"{model}.fmu")
            t_compile = time.perf_counter() - t0
            md = fmpy.read_model_description(str(res.fmu))
            stop = float(md.defaultExperiment.stopTime) if md.defaultExperiment and md.defaultExperiment.stopTime \
                else 3600.0
            # what both runs record and the check compares: the outputs, else the continuous states
            outputs = [v.name for v in md.modelVariables if v.causality == "output"] or \
                [d.variable.derivative.name for d in md.derivatives if d.variable.derivative is not None]
            unzipdir = fmpy.extract(str(res.fmu))
            inst = fmpy.instantiate_fmu(unzipdir, md, fmi_type="ModelExchange")
            last = {}

            def ours() -> None:
                inst.reset()
                last["r"] = fmpy.simulate_fmu(unzipdir, model_description=md, fmu_instance=inst, stop_time=stop,
                                              output_interval=stop / 500, relative_tolerance=1e-6,
                                              output=outputs or None)

            ours_w, ours_c = timed(ours)
            inst.freeInstance()
            rmodel = rumoca.Session().load(str(lib / "package.mo"), model=model)
            peer_w, peer_c = timed(lambda: rmodel.simulate((0.0, stop), dt=stop / 500,
                                                           config=rumoca.SimConfig(rtol=1e-6, atol=1e-6)))
            grid = np.linspace(0.0, stop, 501)
            bounds = [run_bound(res.fmu, grid=grid, outputs=outputs, tolerance=1e-6, max_step=stop / 50)
                      for _ in range(RUNS)]
            bound_w, bound_c = sum(b.wall for b in bounds), sum(b.cpu for b in bounds)
            # the bound and fmpy computed the same trajectory: largest difference over the outputs' ranges
            check = float("nan")
            r = last["r"]
            if outputs and r is not None and len(r) == grid.size:
                check = max(float(np.max(np.abs(r[n] - bounds[0].outputs[:, j])) / (np.ptp(r[n]) or 1.0))
                            for j, n in enumerate(outputs))
            sim = RUNS * stop
            print(f"{model.removeprefix('TrackingBox.Benches.'):56s} {t_compile:9.2f} {sim / ours_w:10.0f} "
                  f"{sim / ours_c:10.0f} {sim / peer_w:10.0f} {sim / peer_c:10.0f} {sim / bound_w:10.0f} "
                  f"{sim / bound_c:10.0f} {peer_w / ours_w:9.2f} {ours_c / bound_c:10.1f} {check:8.1e}")
    print(f"(each speed from {RUNS} runs over the model's stopTime, 500 output intervals, rtol 1e-6; ours/peer: "
          "how many times faster the FMU is than rumoca (wall); bound/ours: how many times less CPU the "
          "no-Python run needs; check: largest |ours - bound| over the recorded variables (outputs, else states) "
          "as a fraction of their range; nan when the grids differ)")
    train()
    return 0


if __name__ == "__main__":
    sys.exit(main())
