#!/usr/bin/env python3
"""Benchmark: the evaporator train's step tests on 1 and 2 workers, process pool and Dask, and per-task overhead.

Builds (once, cached in ``.cache/bench_parallel/``) the ``evaporator-train`` bench
case with ``--effects`` effects, then runs the pairing stage's step tests
(``pair(spec, PairSettings(data_checks=False, second_point="none"))``: the
settle, the reference run and the two-sided step of every candidate parameter)
on each executor:

* ``serial``: 1 worker, this process (the process-pool path's ``--workers 1``);
* ``pool-2``: a local process pool of 2 workers (``--workers 2``);
* ``dask-1``, ``dask-2``: a local Dask cluster of 1 and 2 single-threaded
  workers on 127.0.0.1 (``--scheduler local --workers N``).

Each executor is started (and its workers warmed by trivial tasks) before the
timing, as a cluster is up before a stage uses it; the start-up is printed apart.
It prints each run's wall time and CPU time (this process plus its workers), the
speed-up of 2 workers over 1 for both kinds (target :data:`TARGET`), the
speed-up the one-worker Dask run's task times allow on 2 workers (Amdahl: the
baseline and the reference run each run alone), whether the gain matrices are
identical bit for bit, and the round trip of a trivial task (submit, wait) on
each executor. Exit code 1 when a speed-up misses the target.
This is a benchmark, not a test: on a loaded machine the wall times (and so the
speed-ups) are the machine's, read the CPU times beside them.

Examples::

    scripts/bench_parallel                      # 7 effects (the train's default), 6 h case
    scripts/bench_parallel --effects 3 --json   # a quick check (misses the target: short tasks)
    scripts/bench_parallel --kinds pool         # the process pool only
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / ".cache" / "bench_parallel"
#: speed-up of 2 workers over 1 that the benchmark asks for (issue 11)
TARGET = 1.7


def _noop(x: int) -> int:
    return x


def _worker_cpu() -> float:
    import psutil

    t = psutil.Process().cpu_times()
    return t.user + t.system


def _pool_cpu(ex: Any) -> float:
    """CPU seconds of a process pool's worker processes so far (read before shutdown)."""
    import psutil

    total = 0.0
    for process in (getattr(ex, "_processes", None) or {}).values():
        try:
            t = psutil.Process(process.pid).cpu_times()
            total += t.user + t.system
        except psutil.Error:
            pass
    return total


def _workers_cpu(ex: Any) -> float:
    """CPU seconds of the executor's workers outside this process."""
    from trackingbox.analysis.executor import DaskExecutor

    if isinstance(ex, DaskExecutor):
        return sum(ex.client.run(_worker_cpu).values())
    return _pool_cpu(ex)


def _round_trip(ex: Any, n: int) -> float:
    """Mean seconds of one trivial task submitted and waited for (after a warm-up)."""
    for k in range(4):
        ex.submit(_noop, k).result()
    t = time.perf_counter()
    for k in range(n):
        ex.submit(_noop, k).result()
    return (time.perf_counter() - t) / n


def _executor(kind: str, workers: int) -> Any:
    from trackingbox.analysis.executor import SerialExecutor, make_executor

    if kind == "serial":
        return SerialExecutor()
    return make_executor("local" if kind == "dask" else None, workers)


def _run(spec: Any, kind: str, workers: int, overhead_tasks: int) -> dict[str, Any]:
    """Step tests of *spec* on one executor: wall and CPU seconds, gains, task round trip."""
    from trackingbox.analysis.pair_stage import PairSettings, pair

    t = time.perf_counter()
    ex = _executor(kind, workers)
    try:
        # start every worker before the timing (a cluster is up before a stage uses it)
        list(ex.map(_noop, range(4 * workers)))
        start = time.perf_counter() - t
        cpu_workers0 = _workers_cpu(ex)
        with _task_stream(ex) as stream:
            wall0, cpu0 = time.perf_counter(), time.process_time()
            result = pair(spec, PairSettings(data_checks=False, second_point="none"), executor=ex)
            wall = time.perf_counter() - wall0
        cpu = time.process_time() - cpu0 + _workers_cpu(ex) - cpu_workers0
        trip = _round_trip(ex, overhead_tasks)
    finally:
        ex.shutdown()
    st = result.steptest
    return {"kind": kind, "workers": workers, "start_seconds": start, "wall_seconds": wall, "cpu_seconds": cpu,
            "runs": st.runs, "round_trip_ms": 1e3 * trip, "gains": st.gains,
            "pairs": [(p.variable, p.parameter) for p in result.pairing.pairs],
            "tasks": _task_times(stream)}


def _task_stream(ex: Any) -> Any:
    """Dask's record of the tasks run (start, stop) while the block runs; nothing for other executors."""
    from contextlib import nullcontext

    from trackingbox.analysis.executor import DaskExecutor

    if isinstance(ex, DaskExecutor):
        from dask.distributed import get_task_stream

        return get_task_stream(ex.client)
    return nullcontext(None)


def _task_times(stream: Any) -> list[tuple[float, float]]:
    """``(start, stop)`` of every task's compute, in start order (s from the first)."""
    if stream is None:
        return []
    spans = sorted((s["start"], s["stop"]) for d in stream.data for s in d["startstops"] if s["action"] == "compute")
    t0 = spans[0][0] if spans else 0.0
    return [(a - t0, b - t0) for a, b in spans]


def _bound(tasks: list[tuple[float, float]], workers: int = 2) -> float:
    """Speed-up on *workers* workers that the one-worker task times allow (Amdahl).

    The run submits the baseline, then the reference run, each alone (the first
    two tasks); the rest run side by side. Re-runs against an extended reference
    count as parallel work here, so this is an upper bound.
    """
    durations = [b - a for a, b in tasks]
    if len(durations) < 3:
        return math.nan
    chain, rest = sum(durations[:2]), sum(durations[2:])
    return (chain + rest) / (chain + rest / workers)


def _case(effects: int, hours: float, seed: int) -> Path:
    from trackingbox.benches import make_bench

    out = CACHE / f"train-{effects}e-{hours:g}h-seed{seed}"
    spec = out / "spec.toml"
    if not spec.exists():
        print(f"building the {effects}-effect evaporator-train case in {out} ...", file=sys.stderr, flush=True)
        make_bench("evaporator-train", out, seed=seed, hours=hours, effects=effects)
    return spec


def main() -> int:
    import numpy as np

    from trackingbox.spec import load_spec

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--effects", type=int, default=7,
                        help="effects of the train (default 7, the train's own; 2 or 3 make a quick check whose "
                             "short tasks leave the Amdahl limit near the target)")
    parser.add_argument("--hours", type=float, default=6.0, help="length of the generated case (default 6 h)")
    parser.add_argument("--seed", type=int, default=0, help="bench seed (default 0)")
    parser.add_argument("--spec", type=Path, help="use this spec instead of generating the train case")
    parser.add_argument("--kinds", default="pool,dask", help="comma-separated: pool, dask (default both)")
    parser.add_argument("--overhead-tasks", type=int, default=200, help="trivial tasks timed per executor")
    parser.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    args = parser.parse_args()
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    if not kinds or set(kinds) - {"pool", "dask"}:
        parser.error(f"--kinds: pool and/or dask, got {args.kinds!r}")
    spec_path = args.spec or _case(args.effects, args.hours, args.seed)
    spec = load_spec(spec_path)
    plan = [("serial", 1), ("pool", 2)] if "pool" in kinds else []
    plan += [("dask", 1), ("dask", 2)] if "dask" in kinds else []
    rows = []
    for kind, workers in plan:
        print(f"step tests on {kind} x {workers} ...", file=sys.stderr, flush=True)
        rows.append(_run(spec, kind, workers, args.overhead_tasks))
    by = {(r["kind"], r["workers"]): r for r in rows}
    speedups = {}
    if "pool" in kinds:
        speedups["pool"] = by[("serial", 1)]["wall_seconds"] / by[("pool", 2)]["wall_seconds"]
    if "dask" in kinds:
        speedups["dask"] = by[("dask", 1)]["wall_seconds"] / by[("dask", 2)]["wall_seconds"]
    if ("dask", 1) in by:
        by[("dask", 1)]["amdahl_bound_2"] = _bound(by[("dask", 1)]["tasks"])
    first = rows[0]
    identical = all(np.array_equal(first["gains"], r["gains"], equal_nan=True) and first["pairs"] == r["pairs"]
                    for r in rows[1:])
    ok = all(s >= TARGET for s in speedups.values())
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    doc = {"spec": str(spec_path), "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
           else os.cpu_count(), "load_average_1min": load, "target": TARGET, "speedups": speedups,
           "identical_gains": identical, "ok": ok,
           "runs": [{k: v for k, v in r.items() if k != "gains"} for r in rows]}
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        print(f"step tests of {spec_path} ({first['runs']} runs each); {doc['cores']} cores, "
              f"1-min load {load:.1f} at the end")
        print(f"{'executor':<10} {'workers':>7} {'start s':>8} {'wall s':>8} {'CPU s':>8} {'round trip ms':>14}")
        for r in rows:
            print(f"{r['kind']:<10} {r['workers']:>7} {r['start_seconds']:>8.1f} {r['wall_seconds']:>8.1f} "
                  f"{r['cpu_seconds']:>8.1f} {r['round_trip_ms']:>14.2f}")
        bound = by.get(("dask", 1), {}).get("amdahl_bound_2")
        if bound is not None:
            tasks = by[("dask", 1)]["tasks"]
            print(f"one worker's task times (dask x 1): baseline {tasks[0][1] - tasks[0][0]:.1f} s, reference run "
                  f"{tasks[1][1] - tasks[1][0]:.1f} s (each alone), {len(tasks) - 2} more tasks "
                  f"{sum(b - a for a, b in tasks[2:]):.1f} s: at most {bound:.2f}x on 2 workers")
        for kind, s in speedups.items():
            print(f"speed-up of 2 workers over 1 ({kind}): {s:.2f}x (target {TARGET}x){'' if s >= TARGET else ': MISSED'}")
        print(f"gain matrices and pairs identical on every executor: {'yes' if identical else 'NO'}")
    return 0 if ok and identical else 1


if __name__ == "__main__":
    sys.exit(main())
