#!/usr/bin/env python3
"""Benchmark: tracking speed per bench beside the plain twin and the no-Python lower bound.

From one tracking run per bench (``TrackingLoop``, as ``trackingbox track``
runs it, pairs found by ``trackingbox pair`` the way a user would), it prints:

* ours: the whole tracking run, wall and CPU seconds (set-up included);
* plain: the untracked twin the runtime steps in lockstep in the same run
  (same FMU, parameters and inputs, no controllers), wall seconds of its steps;
* bound: the same untracked twin integrated by a C driver with no Python in
  the loop (``scripts/_bound.py``: same CVODE, settings, inputs and output
  grid), wall and CPU seconds of its integration loop, and how far its outputs
  are from the plain twin's column in ``tracking.csv`` (a check that it is the
  same computation);
* the ratios run/plain, run/bound and plain/bound;
* which stepper ran the twins (``NativeStepper``: CVODE and the right-hand
  side in C, ``trackingbox.native``; or ``ModelExchangeStepper``, the Python
  path, with the reason; ``TRACKINGBOX_NATIVE=0`` forces it) and, with the
  native stepper, the CPU seconds spent inside its C calls over the run (both
  twins' integration, sub-steps and parameter changes: what the integrator
  alone cost in *this* run, the floor under ours for this work).

There is no peer for tracking (no other tool runs parameter controllers on an
FMU twin); the column says so.

Memory (``--memory-days``, default ``1,7``, heat exchanger only): the peak
resident set (``ru_maxrss`` from ``wait4``) of one ``trackingbox track`` child
process per run length, with the same pairs; the growth from the shortest to
the longest run is printed beside it, and the script exits 1 when that growth
exceeds ``--memory-allowance`` MiB (default :data:`MEMORY_ALLOWANCE_MIB`): the
issue's "the 7-day run needs no more than the 1-day one plus a small constant".

This is a benchmark, not a test: minutes to tens of minutes.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bound import run_bound  # noqa: E402

from trackingbox.benches import BENCHES, make_bench  # noqa: E402
from trackingbox.spec import load_spec, write_pairs  # noqa: E402
from trackingbox.tracking.runtime import TrackingLoop  # noqa: E402


#: Most the peak RSS of the longest memory run may exceed the shortest's (MiB). What still grows
#: with the run's length is the measurement view's float arrays and the twins' input tables, some
#: twenty floats per sample: measured on the heat exchanger (10 s samples, loaded machine) 90.8 MiB
#: for 1 day and 103.3 MiB for 7 days, +2.1 MiB per extra day (before the chunked CSV read: 92.6
#: and 125.6). 16 MiB covers 1 day -> 7 days with room for the allocator's noise; it is not a
#: bound for much longer runs (a windowed measurement view would be).
MEMORY_ALLOWANCE_MIB = 16.0


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def pairs_for(spec_path: Path, bench: str, freeze_controllers: bool) -> None:
    """Benches ship without [[pairs]]: pair them the way the demo does (``trackingbox pair`` writes them).

    The spec's ``[pairing] freeze`` when it has one (the evaporator: the level loops of the
    flash and condensate tanks); else every controller frozen (``holdControllers=1``, the
    source's method) on the demo's :data:`~trackingbox.demo.FREEZE_CONTROLLERS` benches or
    with ``--freeze-controllers``; else closed-loop step tests (the demo's choice for heat
    production, where a frozen twin leaves most tags unobservable: issue 15).
    """
    from trackingbox.demo import FREEZE_CONTROLLERS
    from trackingbox.fmu import read_info

    spec = load_spec(spec_path)
    names = {getattr(v, "name", v) for v in read_info(spec.twin).inputs}
    freeze = []
    if not spec.pairing.freeze and "holdControllers" in names and (freeze_controllers or bench in FREEZE_CONTROLLERS):
        freeze = ["--freeze", "holdControllers=1"]
    cmd = [sys.executable, "-m", "trackingbox.cli", "pair", str(spec_path), "--workers", "2", *freeze]
    log(" ".join(cmd[2:]))
    rc = subprocess.run(cmd, stdout=sys.stderr).returncode
    if rc != 0:
        sys.exit(f"bench_tracking: trackingbox pair found no usable pairs on {spec_path} (exit {rc}); "
                 f"command: {' '.join(cmd[2:])}")
    if spec.source is not None and "Evaporator" in spec.source.model:
        from trackingbox.benches.evaporator import CLOSED_LOOP, slow_pairs  # the demo's tuning of this bench

        slow_pairs(spec_path, spec.pairing.closed_loop or CLOSED_LOOP)


def cpu_now() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def track_with_bound(name: str, spec_path: Path, out: Path) -> dict:
    """One tracking run, its lockstep plain twin, and the bound on the same twin, inputs and grid."""
    from trackingbox import native

    spec = load_spec(spec_path)
    c0, w0, n0 = cpu_now(), time.perf_counter(), native.cpu_seconds()
    loop = TrackingLoop(spec, out_dir=out, checkpoint_every=10**9)
    try:
        loop.begin()
        plain = loop.plain
        assert plain is not None
        base = dict(plain.base)
        base.update(plain.applied)  # the corrections it starts with (0)
        inputs = plain.inputs
        stepper = type(loop.twin.stepper).__name__
        reason = loop.twin.model.native_reason
        loop.run()
    finally:
        loop.close()
    result = loop.result()
    wall, cpu = time.perf_counter() - w0, cpu_now() - c0
    in_c = native.cpu_seconds() - n0
    grid = np.asarray(loop.grid, dtype=float)
    if grid[0] > 0.0:  # the twins start at 0
        grid = np.concatenate(([0.0], grid))
    read = list(loop.read)
    bound = run_bound(spec.twin, grid=grid, outputs=read, parameters=base, inputs=inputs)
    import pandas as pd

    df = pd.read_csv(result.csv)
    worst = 0.0
    for tag in loop.plan.out_tags:
        col = df[f"untracked:{tag}"].to_numpy(float)
        j = read.index(loop.plan.tag_var[tag])
        b = bound.outputs[grid.size - col.size:, j]
        span = float(np.nanmax(col) - np.nanmin(col)) or 1.0
        worst = max(worst, float(np.nanmax(np.abs(col - b))) / span)
    return {"bench": name, "rows": result.steps, "sim": result.simulated_seconds, "wall": wall, "cpu": cpu,
            "plain": result.seconds_untracked, "bound_wall": bound.wall, "bound_cpu": bound.cpu,
            "bound_steps": bound.steps, "bound_rhs": bound.rhs, "check": worst,
            "states": len(spec.states), "pairs": [(p.variable, p.parameter) for p in spec.pairs],
            "stepper": stepper, "reason": reason, "in_c": in_c, "substeps": loop.substeps}


#: Starts the measured command and prints its ``ru_maxrss`` (kB) and exit code: a small process, so
#: that the figure is the command's own. A child forked straight from this script would inherit
#: the script's resident set as its high-water mark at ``exec`` (Linux records the old address
#: space's peak in the child's ``maxrss``): after building a 7-day case in-process that read
#: 155 MiB for the 1-day run, whose own peak is about 90.
LAUNCHER = """
import os, sys
pid = os.posix_spawn(sys.argv[1], sys.argv[1:], os.environ)
_, status, usage = os.wait4(pid, 0)
print(usage.ru_maxrss, os.waitstatus_to_exitcode(status))
"""


def peak_rss(spec_path: Path, out: Path) -> tuple[int, float, int, int]:
    """``trackingbox track`` in a child process: its peak RSS (kB), wall seconds, exit code, rows written."""
    env = {**os.environ, "TRACKINGBOX_SUPERVISE": "0", "TRACKINGBOX_CANARY": "0"}
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "trackingbox.cli", "track", str(spec_path), "--out", str(out)]
    proc = subprocess.run([sys.executable, "-S", "-c", LAUNCHER, *cmd], env=env, stdout=subprocess.PIPE, text=True)
    fields = proc.stdout.split()[-2:] if proc.returncode == 0 else []
    rss, rc = (int(fields[0]), int(fields[1])) if len(fields) == 2 else (0, proc.returncode or 1)
    csv = out / "tracking.csv"
    rows = sum(1 for _ in csv.open()) - 1 if csv.exists() else 0
    return rss, time.perf_counter() - t0, rc, rows


def main() -> int:
    ap = argparse.ArgumentParser(prog="bench_tracking")
    ap.add_argument("benches", nargs="*", default=list(BENCHES))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--hours", type=float, default=None, help="measured period (default: each bench's own)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the cases and runs in this directory")
    ap.add_argument("--memory-days", default="1,7",
                    help="heat exchanger: run lengths (days) whose peak memory is measured, comma-separated; "
                         "'' to skip (default 1,7)")
    ap.add_argument("--memory-allowance", type=float, default=MEMORY_ALLOWANCE_MIB, metavar="MIB",
                    help="exit 1 when the longest memory run's peak exceeds the shortest's by more than this "
                         f"(MiB, default {MEMORY_ALLOWANCE_MIB:g})")
    ap.add_argument("--freeze-controllers", action="store_true",
                    help="pair with every controller of the twin frozen (holdControllers=1, the source's method) "
                         "where the spec has no [pairing] freeze; default: as the demo pairs each bench")
    args = ap.parse_args()
    unknown = [b for b in args.benches if b not in BENCHES]
    if unknown:
        ap.error(f"unknown bench {unknown}; known: {list(BENCHES)}")
    try:
        days = [float(d) for d in args.memory_days.split(",") if d.strip()]
    except ValueError:
        ap.error(f"--memory-days {args.memory_days!r}: expected numbers separated by commas")

    rows, memory = [], []
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        for name in args.benches:
            log(f"{name}: building the case ...")
            case = make_bench(name, root / name, seed=args.seed, hours=args.hours)
            if not load_spec(case.spec).pairs:
                pairs_for(case.spec, name, args.freeze_controllers)
            log(f"{name}: tracking ...")
            rows.append(track_with_bound(name, case.spec, root / name / "track"))
            if name == "heat-exchanger" and days:
                pairs = load_spec(case.spec).pairs
                for d in days:
                    log(f"{name}: {d:g}-day case for the memory figure ...")
                    long = make_bench(name, root / f"{name}-{d:g}d", seed=args.seed, hours=24.0 * d,
                                      plant_fmu=case.plant_fmu, twin_fmu=case.twin_fmu)
                    write_pairs(long.spec, pairs)
                    rss, wall, rc, n = peak_rss(long.spec, root / f"{name}-{d:g}d" / "track")
                    if rc != 0:
                        sys.exit(f"bench_tracking: trackingbox track failed on {long.spec} (exit {rc})")
                    memory.append((d, rss, wall, n))

    print("tracking: ours = the whole Python tracking run; plain = its lockstep untracked twin; "
          "bound = that twin with no Python in the loop (C driver, same CVODE/settings/inputs/grid)")
    print("peer: none (no other tool tracks parameters online on an FMU twin)")
    head = (f"{'bench':16s} {'rows':>6s} {'sim s':>7s} {'ours wall':>9s} {'ours CPU':>8s} {'plain wall':>10s} "
            f"{'bound wall':>10s} {'bound CPU':>9s} {'ours/plain':>10s} {'ours/bound':>10s} "
            f"{'ours/bound CPU':>14s} {'plain/bound':>11s} {'bound check':>11s} {'x real time':>11s}")
    print(head)
    for r in rows:
        print(f"{r['bench']:16s} {r['rows']:6d} {r['sim']:7.0f} {r['wall']:9.2f} {r['cpu']:8.2f} {r['plain']:10.2f} "
              f"{r['bound_wall']:10.3f} {r['bound_cpu']:9.3f} {r['wall'] / r['plain']:10.2f} "
              f"{r['wall'] / r['bound_wall']:10.1f} {r['cpu'] / r['bound_cpu']:14.1f} "
              f"{r['plain'] / r['bound_wall']:11.1f} {r['check']:11.1e} {r['sim'] / r['wall']:11.0f}")
    print("(x real time = sim s / ours wall, simulated seconds per wall second of the whole tracking run; "
          "bound check = largest |plain - bound| over the run as a fraction of the tag's range; the bound times "
          "CVODE's integration loop only)")
    print(f"\n{'bench':16s} {'stepper':20s} {'sub-steps':>9s} {'integrator CPU':>14s} {'ours CPU/integrator':>19s}")
    for r in rows:
        integ = f"{r['in_c']:14.3f}" if r["in_c"] > 0 else f"{'-':>14s}"
        ratio = f"{r['cpu'] / r['in_c']:19.1f}" if r["in_c"] > 0 else f"{'-':>19s}"
        print(f"{r['bench']:16s} {r['stepper']:20s} {r['substeps']:9d} {integ} {ratio}")
        if r["reason"]:
            print(f"  ({r['bench']}: Python path because {r['reason']})")
    print("(integrator CPU = CPU inside the native stepper's C calls over the run, both twins: CVODE, the "
          "FMU's right-hand side, parameter changes; the plain twin runs on the same stepper as ours; "
          "TRACKINGBOX_NATIVE=0 runs both on the Python path)")
    for r in rows:
        if r["states"]:
            print(f"note: {r['bench']} has state compensation: the bound runs with its corrections at 0")
    if memory:
        print("\nmemory: peak RSS of one `trackingbox track` child process (heat exchanger, same pairs)")
        print(f"{'days':>5s} {'rows':>7s} {'peak RSS MiB':>12s} {'wall s':>7s}")
        for d, rss, wall, n in memory:
            print(f"{d:5g} {n:7d} {rss / 1024:12.1f} {wall:7.0f}")
        if len(memory) > 1:
            (d0, r0, *_), (d1, r1, *_) = min(memory), max(memory)
            growth = (r1 - r0) / 1024
            print(f"growth {d0:g} d -> {d1:g} d: {growth:+.1f} MiB "
                  f"({growth / (d1 - d0):+.2f} MiB per extra day); allowed: +{args.memory_allowance:g} MiB")
            if growth > args.memory_allowance:
                print(f"FAIL: the {d1:g}-day run's peak ({r1 / 1024:.1f} MiB) exceeds the {d0:g}-day run's "
                      f"({r0 / 1024:.1f} MiB) by more than {args.memory_allowance:g} MiB")
                return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
