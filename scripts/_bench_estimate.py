#!/usr/bin/env python3
"""Benchmark: trackingbox's estimator beside ModestPy 0.1.1 on the same FMU, data, parameters and bounds.

Runs both on the training window of a bench case (or any spec), then judges
both estimates with the *same* yardstick -- trackingbox's validation NRMSE per
tag (RMSE / measured range, warm-up before the window, masked samples left
out) -- and prints wall time and validation NRMSE side by side with ratios.

ModestPy needs ``pandas<2`` and ``pyDOE==0.3.8``, so it runs in its own virtual
environment (created on first use under ``.cache/modestpy-venv``) through a small
runner script this file writes next to the case. What the runner does, so that
both tools fit the same samples:

* inputs: the training window's inputs on the ``sample_time`` grid, preceded by
  the same steady-state pre-run (inputs held at their first values for the
  warm-up) that trackingbox uses; ModestPy's FMU start is the twin's own start;
* ideal: the measured outputs on the same grid;
* ModestPy's error function is restricted to the samples after the pre-run that
  trackingbox also uses (not NaN, not masked); otherwise it is ModestPy's own
  (``ftype="NRMSE"``: RMSE / mean |measured|, summed over tags);
* methods ``("MODESTGA", "SCIPY")``: its parallel GA, then L-BFGS-B, the pipeline
  the source thesis describes (GA, then gradient-based refinement).

This is a benchmark, not a test: it takes minutes.

Examples::

    scripts/bench_estimate                                   # heat-exchanger bench, seed 0
    scripts/bench_estimate --bench heat-production --workers 2
    scripts/bench_estimate --spec case1/spec.toml --json
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
CACHE = ROOT / ".cache"
VENV = CACHE / "modestpy-venv"
MODESTPY_REQUIREMENTS = ["modestpy==0.1.1", "pandas<2", "pyDOE==0.3.8", "numpy<2"]

RUNNER = r'''
"""Run ModestPy 0.1.1 on one estimation job (written by scripts/bench_estimate)."""
import json, sys, time, os
import numpy as np
import pandas as pd

job = json.load(open(sys.argv[1]))
os.chdir(job["workdir"])
import modestpy
import modestpy.estim.error as error_module
from modestpy import Estimation

warmup = float(job["warmup"])
original = error_module.calc_err


def calc_err_after_warmup(result, ideal, forgetting=False, ftype="RMSE"):
    # the samples trackingbox's cost uses: after the pre-run, measured value present
    keep = (ideal.index >= warmup - 1e-9) & ideal.notna().all(axis=1).to_numpy()
    ideal = ideal.loc[keep]
    result = result.loc[result.index.isin(ideal.index)]
    return original(result, ideal, forgetting=forgetting, ftype=ftype)


import modestpy.estim.ga_parallel.ga_parallel as m1, modestpy.estim.ps.ps as m2
import modestpy.estim.scipy.scipy as m3, modestpy.estim.ga.individual as m4
for module in (m1, m2, m3, m4, error_module):
    module.calc_err = calc_err_after_warmup

import modestpy.fmi.model as model_module
_simulate = model_module.simulate_fmu


def counted_simulate(*a, **k):
    # one byte per FMU run, appended (GA workers are separate processes)
    with open(os.path.join(job["workdir"], "fmu_runs.count"), "ab") as fh:
        fh.write(b"1")
    return _simulate(*a, **k)


model_module.simulate_fmu = counted_simulate
inp = pd.read_csv(job["inputs"]).set_index("time")
ideal = pd.read_csv(job["ideal"]).set_index("time")
est = {k: tuple(v) for k, v in job["est"].items()}
t0 = time.perf_counter()
session = Estimation(job["workdir"], job["fmu"], inp, job["known"], est, ideal,
                     methods=tuple(job["methods"]), modestga_opts=job["modestga_opts"],
                     scipy_opts=job["scipy_opts"], ftype="NRMSE", default_log=True,
                     logfile=os.path.join(job["workdir"], "modestpy.log"))
estimates = session.estimate()
seconds = time.perf_counter() - t0
out = {"parameters": {k: float(v) for k, v in estimates.items()}, "seconds": seconds,
       "modestpy_version": getattr(modestpy, "__version__", "0.1.1"),
       "pandas_version": pd.__version__}
try:
    summary = pd.read_csv(os.path.join(job["workdir"], "summary_1.csv"))
    out["iterations"] = int(len(summary))
    out["modestpy_error"] = float(summary["_error_"].iloc[-1])
except Exception as exc:  # the summary is a nicety
    out["summary_error"] = str(exc)
count = os.path.join(job["workdir"], "fmu_runs.count")
out["fmu_runs"] = os.path.getsize(count) if os.path.exists(count) else 0
json.dump(out, open(job["result"], "w"), indent=2)
'''


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def ensure_venv(venv: Path) -> Path:
    python = venv / "bin" / "python"
    if python.exists():
        probe = subprocess.run([str(python), "-c", "import modestpy, pyDOE, pandas; print(pandas.__version__)"],
                               capture_output=True, text=True)
        if probe.returncode == 0:
            return python
    log(f"creating ModestPy environment in {venv} ({' '.join(MODESTPY_REQUIREMENTS)}) ...")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    subprocess.run([str(python), "-m", "pip", "install", "-q", *MODESTPY_REQUIREMENTS], check=True)
    return python


def make_case(bench: str, seed: int, overrides: dict[str, float] | None) -> Path:
    from trackingbox.benches import make_bench

    tag = "-".join(f"{k}={v:g}" for k, v in sorted((overrides or {}).items()))
    out = CACHE / "bench_estimate" / f"{bench}-seed{seed}{'-' + tag if tag else ''}"
    spec = out / "spec.toml"
    if not spec.exists():
        log(f"building bench case {bench} (seed {seed}) in {out} ...")
        make_bench(bench, out, seed=seed, overrides=overrides)
    return spec


def window_table(problem, window, dt: float):
    """A window as one run from 0: the held-input pre-run then the window (times, inputs dict, offset, n_pre)."""
    import numpy as np

    lead_in = float(window.start - window.time[0])  # measured history before the window
    offset = math.ceil(max(0.0, problem.warmup - lead_in) / dt - 1e-9) * dt  # held-input pre-run
    n_pre = int(round(offset / dt))
    grid = window.time - window.time[0]
    t = np.concatenate((np.arange(n_pre) * dt, offset + grid))
    inputs = {"time": t}
    for name, values in window.inputs.items():
        inputs[name] = np.concatenate((np.full(n_pre, values[0]), values))
    return t, inputs, offset, n_pre, lead_in


def bound_run(problem, window, dt: float):
    """The no-Python lower bound of one twin run over *window* (pre-run included) at the start values."""
    import pandas as pd
    from _bound import run_bound

    t, inputs, *_ = window_table(problem, window, dt)
    params = {**dict(problem.fixed), **dict(zip(problem.names, map(float, problem.start)))}
    return run_bound(problem.twin, grid=t, outputs=list(dict.fromkeys(problem.outputs.values())),
                     parameters=params, inputs=pd.DataFrame(inputs))


def cpu_now() -> float:
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def modestpy_job(spec, problem, training, workdir: Path, workers: int, generations: int, pop: int) -> dict:
    import numpy as np
    import pandas as pd

    t, inputs, offset, n_pre, lead_in = window_table(problem, training, problem.sample_time)
    ideal = {"time": t}
    for tag, name in problem.outputs.items():
        ideal[name] = np.concatenate((np.full(n_pre, np.nan), training.measured[tag]))
    workdir.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(inputs).to_csv(workdir / "inputs.csv", index=False)
    pd.DataFrame(ideal).to_csv(workdir / "ideal.csv", index=False)
    return {
        "fmu": str(problem.twin),
        "inputs": str(workdir / "inputs.csv"),
        "ideal": str(workdir / "ideal.csv"),
        "known": dict(problem.fixed),
        "est": {n: [float(s), float(lo), float(hi)]
                for n, s, lo, hi in zip(problem.names, problem.start, problem.lower, problem.upper)},
        "warmup": offset + lead_in,  # ModestPy time at which the scored window starts
        "methods": ["MODESTGA", "SCIPY"],
        "modestga_opts": {"workers": workers, "generations": generations, "pop_size": pop},
        "scipy_opts": {},
        "workdir": str(workdir),
        "result": str(workdir / "modestpy_result.json"),
    }


def _arguments() -> argparse.Namespace:
    """The command line (a bench named by position is the same as --bench)."""
    from trackingbox.estimation import MAX_REFINE_ITERATIONS

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("bench_name", nargs="?", metavar="BENCH", help="bench to generate (same as --bench)")
    parser.add_argument("--bench", default="heat-exchanger", help="bench to generate (default heat-exchanger)")
    parser.add_argument("--spec", type=Path, help="use this spec instead of generating a bench case")
    parser.add_argument("--seed", type=int, default=0, help="bench seed and estimator seed (default 0)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="plant parameter override for the generated bench (repeatable)")
    parser.add_argument("--workers", type=int, default=1, help="worker processes for both tools (default 1)")
    parser.add_argument("--maxiter", type=int, default=None, help="trackingbox: DE generations")
    parser.add_argument("--popsize", type=int, default=None, help="trackingbox: DE population per parameter")
    parser.add_argument("--refine-iterations", type=int, default=MAX_REFINE_ITERATIONS,
                        help=f"trackingbox: least-squares iterations (default {MAX_REFINE_ITERATIONS})")
    parser.add_argument("--generations", type=int, default=50, help="ModestPy MODESTGA generations (default 50, its own)")
    parser.add_argument("--pop", type=int, default=30, help="ModestPy MODESTGA population (default 30, its own)")
    parser.add_argument("--skip-modestpy", action="store_true", help="run only trackingbox's estimator")
    parser.add_argument("--venv", type=Path, default=VENV, help=f"ModestPy virtual environment (default {VENV})")
    parser.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    args = parser.parse_args()
    if args.bench_name:
        args.bench = args.bench_name
    return args


def main() -> int:
    args = _arguments()

    import numpy as np

    from trackingbox.estimation import Objective, estimate, load_windows, problem_from_spec
    from trackingbox.spec import load_spec

    overrides = {}
    for item in args.set:
        name, _, value = item.partition("=")
        overrides[name] = float(value)
    spec_path = args.spec or make_case(args.bench, args.seed, overrides or None)
    spec = load_spec(spec_path)
    problem = problem_from_spec(spec)
    training, validation = load_windows(spec, warmup=problem.warmup)
    work = spec_path.parent / "bench_estimate"
    tags = list(problem.outputs)

    log(f"trackingbox estimate on {spec_path} ...")
    t0, c0 = time.perf_counter(), cpu_now()
    ours = estimate(spec, seed=args.seed, workers=args.workers, maxiter=args.maxiter, popsize=args.popsize,
                    refine_iterations=args.refine_iterations)
    ours_wall, ours_cpu = time.perf_counter() - t0, cpu_now() - c0
    rows = {"trackingbox": {
        "seconds": ours_wall, "cpu_seconds": ours_cpu, "evaluations": ours.evaluations, "parameters": ours.parameters,
        "training_nrmse": ours.training_nrmse, "validation_nrmse": ours.validation_nrmse,
        "refinement": ours.refinement}}
    blocked = None
    if not args.skip_modestpy:
        try:
            python = ensure_venv(args.venv)
            job = modestpy_job(spec, problem, training, work / "modestpy", args.workers, args.generations, args.pop)
            job_file = work / "modestpy" / "job.json"
            job_file.write_text(json.dumps(job, indent=2))
            runner = work / "modestpy" / "run_modestpy.py"
            runner.write_text(RUNNER)
            (work / "modestpy" / "fmu_runs.count").unlink(missing_ok=True)
            log(f"ModestPy 0.1.1 (MODESTGA generations={args.generations} pop={args.pop}, then SCIPY) ...")
            t0, c0 = time.perf_counter(), cpu_now()
            proc = subprocess.run([str(python), str(runner), str(job_file)], capture_output=True, text=True,
                                  env={**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": ""})
            mp_wall, mp_cpu = time.perf_counter() - t0, cpu_now() - c0
            if proc.returncode != 0:
                tail = "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-15:])
                raise RuntimeError(f"ModestPy run failed (exit {proc.returncode}):\n{tail}")
            mp = json.loads(Path(job["result"]).read_text())
            x = np.array([mp["parameters"][n] for n in problem.names])
            rows["modestpy"] = {
                "seconds": mp_wall, "cpu_seconds": mp_cpu, "evaluations": mp.get("fmu_runs"),
                "seconds_inside": mp["seconds"], "iterations": mp.get("iterations"),
                "parameters": mp["parameters"],
                "training_nrmse": Objective(problem, training).nrmse(x),
                "validation_nrmse": Objective(problem, validation).nrmse(x)}
        except Exception as exc:  # a benchmark reports what blocked it instead of dying silently
            blocked = f"{type(exc).__name__}: {exc}"
    initial = Objective(problem, validation).nrmse(problem.start)
    # the no-Python bound: one twin run of the training window on the full grid and on the global
    # search's coarse grid, by the C driver; the estimator's runs cost at least the coarse one each
    from trackingbox.estimation import DEFAULT_GLOBAL_GRID, coarsen

    stride = max(1, int(math.floor(DEFAULT_GLOBAL_GRID / problem.sample_time + 1e-9)))
    full = bound_run(problem, training, problem.sample_time)
    coarse = bound_run(problem, coarsen(training, stride), problem.sample_time * stride)
    n = rows["trackingbox"]["evaluations"]
    rows["bound"] = {"full_run_wall": full.wall, "full_run_cpu": full.cpu,
                     "coarse_run_wall": coarse.wall, "coarse_run_cpu": coarse.cpu, "stride": stride,
                     "seconds": n * min(coarse.wall, full.wall), "cpu_seconds": n * min(coarse.cpu, full.cpu),
                     "evaluations": n}

    def mean(d: dict) -> float:
        return float(np.mean(list(d.values())))

    doc = {"spec": str(spec_path), "parameters": list(problem.names), "validation_nrmse_initial": initial,
           "runs": rows, "modestpy_blocked": blocked}
    if "modestpy" in rows:
        doc["ratio"] = {
            "wall_time_modestpy_over_trackingbox": rows["modestpy"]["seconds"] / rows["trackingbox"]["seconds"],
            "validation_nrmse_modestpy_over_trackingbox":
                mean(rows["modestpy"]["validation_nrmse"]) / mean(rows["trackingbox"]["validation_nrmse"]),
        }
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0 if blocked is None else 1
    print(f"case: {spec_path}")
    print("validation NRMSE at the start values: "
          + ", ".join(f"{t} {v:.4g}" for t, v in initial.items()))
    width = max(12, *(len(n) for n in problem.names))
    print(f"\n{'':<{width}}  {'trackingbox':>14}  {'ModestPy 0.1.1':>14}")
    mp_row = rows.get("modestpy")
    print(f"{'wall time (s)':<{width}}  {rows['trackingbox']['seconds']:>14.1f}  "
          f"{(mp_row['seconds'] if mp_row else float('nan')):>14.1f}")
    for n in problem.names:
        print(f"{n:<{width}}  {ours.parameters[n]:>14.6g}  "
              f"{(mp_row['parameters'][n] if mp_row else float('nan')):>14.6g}")
    for t in tags:
        print(f"{'train ' + t:<{width}}  {ours.training_nrmse[t]:>14.4g}  "
              f"{(mp_row['training_nrmse'][t] if mp_row else float('nan')):>14.4g}")
        print(f"{'valid ' + t:<{width}}  {ours.validation_nrmse[t]:>14.4g}  "
              f"{(mp_row['validation_nrmse'][t] if mp_row else float('nan')):>14.4g}")
    b, o = rows["bound"], rows["trackingbox"]
    print(f"\n{'':<24}  {'ours':>12}  {'peer':>12}  {'bound':>12}   ours = trackingbox, peer = ModestPy 0.1.1,")
    print(f"{'wall s':<24}  {o['seconds']:>12.1f}  {(mp_row['seconds'] if mp_row else float('nan')):>12.1f}  "
          f"{b['seconds']:>12.2f}   bound = ours' FMU runs, each at the")
    print(f"{'CPU s':<24}  {o['cpu_seconds']:>12.1f}  {(mp_row['cpu_seconds'] if mp_row else float('nan')):>12.1f}  "
          f"{b['cpu_seconds']:>12.2f}   cost of one no-Python run of the")
    mp_runs = mp_row.get("evaluations") if mp_row else None
    print(f"{'FMU runs':<24}  {o['evaluations']:>12d}  {(mp_runs if mp_runs is not None else float('nan')):>12}  "
          f"{b['evaluations']:>12d}   training window on the coarse grid")
    print(f"{'CPU s per FMU run':<24}  {o['cpu_seconds'] / max(o['evaluations'], 1):>12.4f}  "
          f"{(mp_row['cpu_seconds'] / mp_runs if mp_row and mp_runs else float('nan')):>12.4f}  "
          f"{b['cpu_seconds'] / max(b['evaluations'], 1):>12.4f}   (global search's, {b['stride']}x the sample;")
    print(f"{'mean validation NRMSE':<24}  {mean(o['validation_nrmse']):>12.4g}  "
          f"{(mean(mp_row['validation_nrmse']) if mp_row else float('nan')):>12.4g}  {'':>12}   "
          f"full-grid run: {b['full_run_cpu']:.4f} s CPU)")
    ref = o.get("refinement") or {}
    if ref:
        print(f"\nours' stages: refinement ({ref.get('jacobian')} Jacobian) {ref.get('runs')} runs, "
              f"{ref.get('seconds', float('nan')):.1f} s wall, {ref.get('cpu_seconds', float('nan')):.1f} s CPU; "
              f"the rest (start, global search, validation) {o['seconds'] - ref.get('seconds', 0.0):.1f} s wall, "
              f"{o['cpu_seconds'] - ref.get('cpu_seconds', 0.0):.1f} s CPU")
    if "ratio" in doc:
        r = doc["ratio"]
        print(f"\npeer/ours wall: {r['wall_time_modestpy_over_trackingbox']:.2f}; "
              f"peer/ours CPU: {mp_row['cpu_seconds'] / o['cpu_seconds']:.2f}; "
              f"validation NRMSE peer/ours: {r['validation_nrmse_modestpy_over_trackingbox']:.3f}")
    print(f"ours/bound wall: {o['seconds'] / b['seconds']:.1f}; ours/bound CPU: {o['cpu_seconds'] / b['cpu_seconds']:.1f}"
          f" (the bound counts FMU integration only, at ours' number of runs)")
    if blocked:
        print(f"\nModestPy comparison blocked: {blocked}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
