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

``--msl [MODEL ...]``: compile time and peak memory on the Modelica Standard Library
(``../shared/msl``), each compile a fresh ``trackingbox compile`` process (peak memory: the largest
process of its tree), three ways in one run: *cold* (empty caches: rumoca's parsed files, the
class index, the flat models), *library cached* (a new model against a library compiled from
before: rumoca's parsed files and the class index kept, no flat model), *model cached* (the same
model again: its flat model kept); beside *full library*, rumoca alone flattening the model
from the whole library (what each compile cost before front-end trees). A one-state model built
from ``Modelica.Thermal.HeatTransfer`` components comes first, then MSL examples.
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


ONE_STATE = """model OneState "one heat capacity cooled through a conductance: one state"
  Modelica.Thermal.HeatTransfer.Components.HeatCapacitor capacity(C = 1000, T(start = 350, fixed = true));
  Modelica.Thermal.HeatTransfer.Components.ThermalConductor wall(G = 10);
  Modelica.Thermal.HeatTransfer.Sources.FixedTemperature ambient(T = 290);
equation
  connect(capacity.port, wall.port_a);
  connect(wall.port_b, ambient.port);
  annotation(experiment(StopTime = 500));
end OneState;
"""

MSL_EXAMPLES = (
    "Modelica.Thermal.HeatTransfer.Examples.TwoMasses",
    "Modelica.Thermal.HeatTransfer.Examples.ControlledTemperature",
    "Modelica.Thermal.FluidHeatFlow.Examples.SimpleCooling",
    "Modelica.Blocks.Examples.PID_Controller",
    "Modelica.Electrical.Analog.Examples.ChuaCircuit",
    "Modelica.Mechanics.Rotational.Examples.First",
    "Modelica.Mechanics.Translational.Examples.Damper",
    "Modelica.Thermal.FluidHeatFlow.Examples.PumpAndValve",
)


def _run_measured(cmd: list[str], env: dict[str, str]) -> tuple[float, float, int, str, float]:
    """(wall s, peak MB of the largest process of the tree, exit status, last line of output, CPU s of the
    tree) of *cmd*."""
    import os
    import subprocess

    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    out = proc.stdout.read() if proc.stdout else b""
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    lines = out.decode("utf-8", "replace").strip().splitlines()
    return wall, usage.ru_maxrss / 1024, proc.returncode, (lines[-1] if lines else ""), \
        usage.ru_utime + usage.ru_stime


_FULL_LIBRARY = """
import sys, rumoca
session = rumoca.Session(roots=[sys.argv[1]])
session.load(sys.argv[2], model=sys.argv[3]).to_dict("flat")
"""


def _defining_file(top: Path, model: str) -> str:
    """The file under *top* that defines *model*: ``A/B/C.mo``, else the nearest enclosing package's
    ``A/B.mo`` or ``A/B/package.mo`` (``Modelica.Blocks.Examples`` is written in ``Blocks/package.mo``)."""
    parts = model.split(".")
    for n in range(len(parts), 0, -1):
        for file in (top.joinpath(*parts[:n]).with_suffix(".mo"), top.joinpath(*parts[:n], "package.mo")):
            if file.is_file():
                return str(file)
    raise FileNotFoundError(f"no file under {top} defines {model}")


def msl(models: list[str]) -> int:
    """Compile time and peak memory on the MSL: cold, library cached, model cached, and rumoca alone on
    the whole library (see the module docstring)."""
    import os
    import statistics

    from trackingbox.compiler.msl_harness import default_msl

    root = default_msl()
    if not (root / "package.mo").is_file():
        print(f"error: the Modelica Standard Library is not at {root} (set TRACKINGBOX_MSL)", file=sys.stderr)
        return 2
    tb = str(Path(sys.executable).with_name("trackingbox"))
    import os as _os

    print(f"MSL {root}; each figure one fresh process: wall s / CPU s / peak MB of its largest process "
          f"(load average at start {_os.getloadavg()[0]:.1f} on {_os.cpu_count()} cores)", flush=True)
    print(f"{'model':58s} {'cold':>18s} {'library cached':>18s} {'model cached':>18s} {'full library':>18s} "
          f"{'full/lib':>8s}", flush=True)
    lib_cached: list[float] = []
    failures = 0
    with tempfile.TemporaryDirectory(prefix="tbx-bench-msl-") as tmp:
        # rumoca alone on the whole library, its parsed files cached: warm that cache once (untimed)
        peer_env = {**os.environ, "XDG_CACHE_HOME": str(Path(tmp) / "peer")}
        _run_measured([sys.executable, "-c", _FULL_LIBRARY, str(root.parent),
                       str(root / "Thermal" / "HeatTransfer" / "Examples" / "TwoMasses.mo"),
                       "Modelica.Thermal.HeatTransfer.Examples.TwoMasses"], peer_env)
        one = Path(tmp) / "OneState.mo"
        one.write_text(ONE_STATE)
        cases = [("OneState", str(one), ["--library", str(root)], str(one))]
        for m in models or MSL_EXAMPLES:
            file = _defining_file(root.parent, m)
            cases.append((m, str(root), [], str(file)))
        for k, (model, source, extra, file) in enumerate(cases):
            cache = Path(tmp) / f"cache{k}"  # this model's own caches, empty before its cold run
            base = {**os.environ, "XDG_CACHE_HOME": str(cache), "TRACKINGBOX_CACHE_DIR": str(cache / "tbx")}
            cmd = [tb, "compile", source, "--model", model, "--backend", "embedded", "-o", str(Path(tmp) / "m.fmu"),
                   *extra]
            cold = _run_measured(cmd, base)
            # a new model against the cached library: no flat model kept
            warm = _run_measured(cmd, {**base, "TRACKINGBOX_FRONTEND_CACHE": "0"})
            again = _run_measured(cmd, base)
            full = _run_measured([sys.executable, "-c", _FULL_LIBRARY, str(root.parent), file, model], peer_env)
            bad = [r for r in (cold, warm, again, full) if r[2] != 0]
            if bad:
                failures += 1
                print(f"{model:58s} failed: {bad[0][3][:150]}", flush=True)
                continue
            lib_cached.append(warm[0])
            cell = lambda r: f"{r[0]:5.1f}/{r[4]:5.1f}/{r[1]:5.0f}"  # noqa: E731
            print(f"{model:58s} {cell(cold):>18s} {cell(warm):>18s} {cell(again):>18s} {cell(full):>18s} "
                  f"{full[0] / warm[0]:8.1f}", flush=True)
    print(f"(load average at the end {_os.getloadavg()[0]:.1f})")
    if lib_cached:
        print(f"median compile with the library cached: {statistics.median(lib_cached):.1f} s wall over "
              f"{len(lib_cached)} models (targets: one-state model <= 5 s and <= 400 MB; median <= 15 s)")
    print("(cold: first compile on an empty cache; library cached: rumoca's parsed files and the class index "
          "kept, the flat model not (a new model); model cached: the same model again; full library: rumoca "
          "alone loading and flattening the model from the whole MSL, parsed files cached, i.e. what every "
          "compile cost before; full/lib: how many times longer that takes than a whole compile with the "
          "library cached)")
    return 1 if failures else 0


def main() -> int:
    if {"-h", "--help"} & set(sys.argv[1:]):
        print(__doc__)
        return 0
    unknown = [a for a in sys.argv[1:] if a.startswith("-") and a not in ("--train", "--msl")]
    if unknown:
        print(f"bench_compile: unknown option {unknown[0]} (options: --train, --msl [MODEL ...], --help)",
              file=sys.stderr)
        return 2
    if "--train" in sys.argv[1:]:
        train()
        return 0
    if "--msl" in sys.argv[1:]:
        return msl([a for a in sys.argv[1:] if a != "--msl"])
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
