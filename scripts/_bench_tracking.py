#!/usr/bin/env python3
"""Benchmark: tracking speed per bench beside the plain twin run and the no-Python lower bound.

Per bench (pairs found by ``trackingbox pair`` the way a user would), from one process, it prints:

* ours: the tracking run alone, as issue 12 means "the Python tracking
  runtime": ``TrackingLoop(spec, untracked=False)`` (the tracked twin with
  its parameter controllers, sub-steps and state compensation, the streamed
  CSV, set-up included), wall and CPU seconds;
* plain: the plain twin run over the same grid, separately: the same FMU,
  inputs and stepper (:meth:`FMUModel.stepper`), parameters at their starts
  and corrections at 0, stepped sample by sample with its outputs read at each
  sample, reading the measurements and loading the FMU included (as ours
  includes its set-up), wall and CPU seconds;
* bound: that plain run with no Python in the loop (``scripts/_bound.py``: a C
  driver, same CVODE, settings, inputs and output grid; its integration loop
  only), wall and CPU seconds, and how far its outputs are from the plain
  run's (a check that it is the same computation);
* stops: the plain run stopped exactly at every sample and sub-step as the
  tracked twin is (``carry=True``), no parameter changed: its right-hand sides
  and integrator CPU, the cost of the exact timing alone; and from it the
  *floor* (:func:`exact_timing_floor`): that integrator CPU plus the plain
  run's CPU outside its integrator, the least a tracking run keeping that
  timing could cost, over the plain run and the bound (beside the targets);
* the ratios ours/plain and ours/bound (the issue's targets: at most 1.5 and
  2), in wall and in CPU seconds, and plain/bound;
* track: the run ``trackingbox track`` makes, which also steps an untracked
  twin in lockstep (a second twin run, with its own state compensation) for
  the CSV's untracked columns, wall seconds and its ratio to plain. Before
  this split, the benchmark's "ours" was this run and its "plain" the wall
  time of that lockstep twin's steps inside it (with its corrections, so
  heat production's bound check read 1.1 of a tag's range);
* which stepper ran the twins (``NativeStepper``: CVODE and the right-hand
  side in C, ``trackingbox.native``; or ``ModelExchangeStepper``, the Python
  path, with the reason; ``TRACKINGBOX_NATIVE=0`` forces it), the sub-steps per
  sample, the rows the loop ran in C (``tbn_track_rows``;
  ``TRACKINGBOX_NATIVE_ROWS=0`` keeps them in Python), the tracked twin's
  integrator restarts and carried changes, and the CPU seconds spent inside the
  native stepper's integration over ours (what the integrator alone cost in
  *this* run: the floor under ours for this work) beside the plain run's, and
  the right-hand-side evaluations of both (``native.rhs_evaluations``: the
  integrator's work in FMU calls, which machine load does not change).

There is no peer for tracking (no other tool runs parameter controllers on an
FMU twin); the output says so.

Both controller modes: the tracking run alone is also run with
``controllers="continuous"`` (the box's laws integrated with the twin by CVODE,
on the inputs twin, built before the clock starts), and its ratios to the same
plain and bound runs are printed beside the discrete (default) mode's.

Memory (``--memory-days``, default ``1,7``; ``--memory-benches``, default the heat exchanger and heat
production): the peak
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
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _bound import run_bound  # noqa: E402

from trackingbox.benches import BENCHES, make_bench  # noqa: E402
from trackingbox.spec import load_spec, write_pairs  # noqa: E402
from trackingbox.tracking.runtime import TrackingLoop  # noqa: E402


#: Most the peak RSS of the longest memory run may exceed the shortest's (MiB). ``track`` holds its
#: measurements and the twins' input tables one window of rows at a time (:mod:`trackingbox.stream`),
#: so nothing of size grows with the run's length (the one column held while a percentile is taken,
#: 0.07 MiB a day, and a sparse time index): measured 2026-11-27 (loaded machine, 10 s samples) heat
#: exchanger 90.5 MiB for 1 day, 90.3 for 7; heat production 98.4 and 99.4 (before the windows:
#: 90.8 / 103.3 and 107.6 / 137.5). 16 MiB is kept as the issue's "small constant"; the growth
#: printed is the figure to watch.
MEMORY_ALLOWANCE_MIB = 16.0


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def hold_constants(case, bench: str) -> None:
    """The evaporator benches: hold the candidates the demo estimates and then holds (its ``[fixed]``:
    boiling-point offsets, the train's vents and heat losses) at the plant's values, as the demo's
    pairing sees them after its estimate (which takes the 7-effect train about 40 min: not this
    benchmark's subject, so the truth stands in for it)."""
    from trackingbox.benches.evaporator import fix_parameters
    from trackingbox.demo import bench_estimate_only

    names = [p.name for p in load_spec(case.spec).parameters]
    values = {n: float(case.truth[n]) for n in bench_estimate_only(bench, names) if n in names and n in case.truth}
    if values:
        fix_parameters(case.spec, values)
        log(f"{bench}: held at the plant's values (the demo estimates and holds them): " + ", ".join(sorted(values)))


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


def plain_setup(spec_path: Path) -> tuple:
    """The plain twin run's spec, measurement view and start values (parameters at their starts,
    corrections 0)."""
    from trackingbox.data import MeasurementView

    spec = load_spec(spec_path)
    view = MeasurementView.from_spec(spec, "all", skip=float(spec.tracking.hold_until))
    start = {p.name: p.start for p in spec.parameters} | dict(spec.fixed) | {s.correction: 0.0 for s in spec.states}
    return spec, view, start


def plain_run(spec_path: Path, grid: np.ndarray, read: list[str]
              ) -> tuple[float, float, float, np.ndarray, pd.DataFrame]:
    """The plain twin run: (wall, CPU, integrator CPU, outputs on the grid, its input table), reading the data and
    the FMU included."""
    from trackingbox import native
    from trackingbox.fmu import FMUModel

    out = np.empty((grid.size, len(read)))
    c0, w0, n0 = cpu_now(), time.perf_counter(), native.cpu_seconds()
    spec, view, start = plain_setup(spec_path)
    with FMUModel(spec.twin) as model:
        st = model.stepper(start_time=float(grid[0]), parameters=start, inputs=view.inputs)
        get = st.reader(read) if hasattr(st, "reader") else (lambda: st.get(read))
        out[0] = get()
        for i in range(1, grid.size):
            st.step(float(grid[i]))
            out[i] = get()
    return time.perf_counter() - w0, cpu_now() - c0, native.cpu_seconds() - n0, out, view.inputs


def stops_run(spec_path: Path, grid: np.ndarray, substeps: int) -> tuple[int, float]:
    """The plain twin run stopped where the tracked twin stops: (RHS evaluations, integrator CPU).

    The same FMU, inputs, parameters and stepper as :func:`plain_run`, but with the
    carried path's exact stops (``carry=True``: CVODE's stop time at every target)
    at every sample and sub-step, and no parameter ever changed: what the
    discrete mode's exact timing of the controllers' moves costs the integrator
    before any move is made.
    """
    from trackingbox import native
    from trackingbox.fmu import FMUModel

    spec, view, start = plain_setup(spec_path)
    n = max(int(substeps), 1)
    targets = np.concatenate([np.linspace(grid[i], grid[i + 1], n + 1)[1:] for i in range(grid.size - 1)])
    r0, n0 = native.rhs_evaluations(), native.cpu_seconds()
    with FMUModel(spec.twin) as model:
        st = model.stepper(start_time=float(grid[0]), parameters=start, inputs=view.inputs, carry=True)
        for t in targets:
            st.step(float(t))
    return native.rhs_evaluations() - r0, native.cpu_seconds() - n0


def continuous_run(spec_path: Path, out: Path) -> dict:
    """The tracking run alone with ``controllers="continuous"``: wall, CPU, integrator CPU and counts.

    The inputs twin (the twin compiled with its tracked parameters as inputs) is built before the
    clock starts, once per spec and cached as a user's first run caches it; its compile time is
    reported beside. A spec the mode cannot run gives the reason instead.
    """
    from trackingbox import native
    from trackingbox.errors import TrackingError
    from trackingbox.generate.inputs_twin import inputs_twin

    spec = load_spec(spec_path)
    w0 = time.perf_counter()
    try:
        inputs_twin(spec)
    except TrackingError as exc:
        return {"reason": str(exc).splitlines()[0]}
    compile_wall = time.perf_counter() - w0
    c0, w0, n0, r0 = cpu_now(), time.perf_counter(), native.cpu_seconds(), native.rhs_evaluations()
    loop = TrackingLoop(spec, out_dir=out / "continuous", checkpoint_every=10**9, untracked=False,
                        controllers="continuous")
    try:
        loop.begin()
        loop.run()
    finally:
        loop.close()
    result = loop.result()
    return {"wall": time.perf_counter() - w0, "cpu": cpu_now() - c0, "in_c": native.cpu_seconds() - n0,
            "rhs": native.rhs_evaluations() - r0, "rows": result.steps, "native_rows": loop.native_rows, "restarts": result.restarts,
            "compile_wall": compile_wall, "reason": ""}


def track_with_bound(name: str, spec_path: Path, out: Path) -> dict:
    """The tracking run alone (both modes), the plain twin run and the bound (same twin, inputs and grid),
    then `track`'s run."""
    from trackingbox import native

    spec = load_spec(spec_path)
    c0, w0, n0, r0 = cpu_now(), time.perf_counter(), native.cpu_seconds(), native.rhs_evaluations()
    loop = TrackingLoop(spec, out_dir=out / "alone", checkpoint_every=10**9, untracked=False)
    try:
        loop.begin()
        base = dict(loop.twin.base)
        base.update({c: 0.0 for c in loop.compensation.names})
        stepper = type(loop.twin.stepper).__name__
        reason = loop.twin.model.native_reason
        loop.run()
    finally:
        loop.close()
    result = loop.result()
    wall, cpu = time.perf_counter() - w0, cpu_now() - c0
    in_c, rhs = native.cpu_seconds() - n0, native.rhs_evaluations() - r0
    cont = continuous_run(spec_path, out)
    grid = np.asarray(loop.grid, dtype=float)
    if grid[0] > 0.0:  # the twins start at 0
        grid = np.concatenate(([0.0], grid))
    read = list(loop.read)
    r1 = native.rhs_evaluations()
    p_wall, p_cpu, p_in_c, p_out, inputs = plain_run(spec_path, grid, read)
    p_rhs = native.rhs_evaluations() - r1
    stops_rhs, stops_in_c = stops_run(spec_path, grid, loop.substeps)
    bound = run_bound(spec.twin, grid=grid, outputs=read, parameters=base, inputs=inputs)
    worst = 0.0
    for tag in loop.plan.out_tags:
        j = read.index(loop.plan.tag_var[tag])
        col, b = p_out[:, j], bound.outputs[:, j]
        span = float(np.nanmax(col) - np.nanmin(col)) or 1.0
        worst = max(worst, float(np.nanmax(np.abs(col - b))) / span)
    # the run `trackingbox track` makes: with the untracked twin in lockstep
    w1 = time.perf_counter()
    full = TrackingLoop(spec, out_dir=out / "track", checkpoint_every=10**9)
    try:
        full.begin()
        full.run()
    finally:
        full.close()
    full_result = full.result()
    t_wall = time.perf_counter() - w1
    return {"bench": name, "rows": result.steps, "sim": result.simulated_seconds, "wall": wall, "cpu": cpu,
            "plain_wall": p_wall, "plain_cpu": p_cpu, "plain_in_c": p_in_c,
            "bound_wall": bound.wall, "bound_cpu": bound.cpu,
            "bound_steps": bound.steps, "bound_rhs": bound.rhs, "check": worst,
            "states": len(spec.states), "pairs": [(p.variable, p.parameter) for p in spec.pairs],
            "stepper": stepper, "reason": reason, "in_c": in_c, "substeps": loop.substeps,
            "rhs": rhs, "plain_rhs": p_rhs, "stops_rhs": stops_rhs, "stops_in_c": stops_in_c,
            "native_rows": loop.native_rows, "restarts": result.restarts, "carried": result.carried,
            "track_wall": t_wall, "track_lockstep": full_result.seconds_untracked, "continuous": cont}


#: Starts the measured command and prints its ``ru_maxrss`` (kB), exit code and CPU seconds: a small process, so
#: that the figure is the command's own. A child forked straight from this script would inherit
#: the script's resident set as its high-water mark at ``exec`` (Linux records the old address
#: space's peak in the child's ``maxrss``): after building a 7-day case in-process that read
#: 155 MiB for the 1-day run, whose own peak is about 90.
LAUNCHER = """
import os, sys
pid = os.posix_spawn(sys.argv[1], sys.argv[1:], os.environ)
_, status, usage = os.wait4(pid, 0)
print(usage.ru_maxrss, os.waitstatus_to_exitcode(status), usage.ru_utime + usage.ru_stime)
"""


def peak_rss(spec_path: Path, out: Path) -> tuple[int, float, int, int, float]:
    """``trackingbox track`` in a child process: its peak RSS (kB), wall seconds, exit code, rows written, CPU s."""
    env = {**os.environ, "TRACKINGBOX_SUPERVISE": "0", "TRACKINGBOX_CANARY": "0"}
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "trackingbox.cli", "track", str(spec_path), "--out", str(out)]
    proc = subprocess.run([sys.executable, "-S", "-c", LAUNCHER, *cmd], env=env, stdout=subprocess.PIPE, text=True)
    fields = proc.stdout.split()[-3:] if proc.returncode == 0 else []
    rss, rc, cpu = (int(fields[0]), int(fields[1]), float(fields[2])) if len(fields) == 3 \
        else (0, proc.returncode or 1, 0.0)
    csv = out / "tracking.csv"
    rows = sum(1 for _ in csv.open()) - 1 if csv.exists() else 0
    return rss, time.perf_counter() - t0, rc, rows, cpu


def exact_timing_floor(r: dict) -> float:
    """CPU seconds under which no tracking run with the discrete mode's exact timing can go on this bench.

    The integrator CPU of the plain twin stopped where the tracked twin stops (nothing changed:
    :func:`stops_run`) plus what the plain run spent outside its integrator (loading the FMU,
    reading the data, stepping from Python): the moves, restarts and controllers taken as free
    and our set-up as lean as the plain run's. Against the plain run and the bound it says
    whether the issue's CPU targets are reachable at all while the changes keep their times.
    """
    return float(r["stops_in_c"] + max(r["plain_cpu"] - r["plain_in_c"], 0.0))


def _arguments() -> tuple[argparse.Namespace, list[float], list[str]]:
    """The command line, checked: (arguments, the memory runs' lengths in days, the benches they run on)."""
    ap = argparse.ArgumentParser(prog="bench_tracking")
    ap.add_argument("benches", nargs="*", default=list(BENCHES))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--hours", type=float, default=None, help="measured period (default: each bench's own)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the cases and runs in this directory")
    ap.add_argument("--memory-days", default="1,7",
                    help="run lengths (days) whose peak memory is measured on each of --memory-benches, "
                         "comma-separated; '' to skip (default 1,7)")
    ap.add_argument("--memory-benches", default="heat-exchanger,heat-production",
                    help="benches (of those run) whose peak memory is measured at --memory-days, comma-separated "
                         "(default heat-exchanger,heat-production)")
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
    mem_benches = [b.strip() for b in args.memory_benches.split(",") if b.strip()]
    unknown = [b for b in mem_benches if b not in BENCHES]
    if unknown:
        ap.error(f"--memory-benches: unknown bench {unknown}; known: {list(BENCHES)}")
    return args, days, mem_benches


def main() -> int:
    args, days, mem_benches = _arguments()

    rows, memory = [], []
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        for name in args.benches:
            log(f"{name}: building the case ...")
            case = make_bench(name, root / name, seed=args.seed, hours=args.hours)
            if not load_spec(case.spec).pairs:
                hold_constants(case, name)
                pairs_for(case.spec, name, args.freeze_controllers)
            log(f"{name}: tracking ...")
            rows.append(track_with_bound(name, case.spec, root / name / "track"))
            if name in mem_benches and days:
                pairs = load_spec(case.spec).pairs
                for d in days:
                    log(f"{name}: {d:g}-day case for the memory figure ...")
                    long = make_bench(name, root / f"{name}-{d:g}d", seed=args.seed, hours=24.0 * d,
                                      plant_fmu=case.plant_fmu, twin_fmu=case.twin_fmu)
                    write_pairs(long.spec, pairs)
                    rss, wall, rc, n, cpu = peak_rss(long.spec, root / f"{name}-{d:g}d" / "track")
                    if rc != 0:
                        sys.exit(f"bench_tracking: trackingbox track failed on {long.spec} (exit {rc})")
                    memory.append((name, d, rss, wall, n, cpu))

    print("tracking (issue 12's figures): ours = the tracking run alone (the tracked twin, its controllers, "
          "sub-steps and state compensation, the CSV; set-up included); plain = the plain twin run over the same "
          "grid (same FMU, inputs and stepper, parameters at their starts, corrections 0; reading the data and "
          "loading the FMU included); "
          "bound = that plain run with no Python in the loop (C driver, same CVODE/settings/inputs/grid; its "
          "integration loop only). Targets: ours/plain <= 1.5, ours/bound <= 2")
    print("peer: none (no other tool tracks parameters online on an FMU twin)")
    head = (f"{'bench':16s} {'rows':>6s} {'sim s':>7s} {'ours wall':>9s} {'ours CPU':>8s} {'plain wall':>10s} "
            f"{'plain CPU':>9s} {'bound wall':>10s} {'bound CPU':>9s} {'ours/plain':>10s} {'ours/bound':>10s} "
            f"{'CPU ours/plain':>14s} {'CPU ours/bound':>14s} {'plain/bound':>11s} {'bound check':>11s} "
            f"{'x real time':>11s}")
    print(head)
    for r in rows:
        print(f"{r['bench']:16s} {r['rows']:6d} {r['sim']:7.0f} {r['wall']:9.2f} {r['cpu']:8.2f} "
              f"{r['plain_wall']:10.2f} {r['plain_cpu']:9.2f} {r['bound_wall']:10.3f} {r['bound_cpu']:9.3f} "
              f"{r['wall'] / r['plain_wall']:10.2f} {r['wall'] / r['bound_wall']:10.2f} "
              f"{r['cpu'] / r['plain_cpu']:14.2f} {r['cpu'] / r['bound_cpu']:14.2f} "
              f"{r['plain_wall'] / r['bound_wall']:11.2f} {r['check']:11.1e} {r['sim'] / r['wall']:11.0f}")
    print("(x real time = sim s / ours wall; bound check = largest |plain - bound| over the run as a fraction of "
          "the tag's range)")
    print(f"\n{'bench':16s} {'track wall':>10s} {'track/plain':>11s} {'lockstep twin wall':>18s}")
    for r in rows:
        print(f"{r['bench']:16s} {r['track_wall']:10.2f} {r['track_wall'] / r['plain_wall']:11.2f} "
              f"{r['track_lockstep']:18.2f}")
    print("(track = the run `trackingbox track` makes: ours plus the untracked twin stepped in lockstep for the "
          "CSV's untracked columns, a second twin run with its own state compensation; lockstep twin wall = that "
          "twin's steps inside it, which this benchmark called 'plain' before)")
    print(f"\n{'bench':16s} {'stepper':20s} {'sub-steps':>9s} {'rows in C':>9s} {'restarts':>8s} {'carried':>8s} "
          f"{'integrator CPU':>14s} {'plain integrator CPU':>20s} {'ours CPU/integrator':>19s} {'RHS':>9s} "
          f"{'plain RHS':>9s} {'RHS ours/plain':>14s}")
    for r in rows:
        integ = f"{r['in_c']:14.3f}" if r["in_c"] > 0 else f"{'-':>14s}"
        pinteg = f"{r['plain_in_c']:20.3f}" if r["plain_in_c"] > 0 else f"{'-':>20s}"
        ratio = f"{r['cpu'] / r['in_c']:19.2f}" if r["in_c"] > 0 else f"{'-':>19s}"
        rhs_ratio = f"{r['rhs'] / r['plain_rhs']:14.2f}" if r["plain_rhs"] > 0 else f"{'-':>14s}"
        print(f"{r['bench']:16s} {r['stepper']:20s} {r['substeps']:9d} {r['native_rows']:9d} {r['restarts']:8d} "
              f"{r['carried']:8d} {integ} {pinteg} {ratio} {r['rhs']:9d} {r['plain_rhs']:9d} {rhs_ratio}")
        if r["reason"]:
            print(f"  ({r['bench']}: Python path because {r['reason']})")
    print("(integrator CPU = CPU inside the native stepper's C calls over ours: CVODE, the FMU's right-hand side, "
          "parameter changes; plain integrator CPU = the same over the plain run; RHS = right-hand-side evaluations "
          "(FMU derivative calls: steps, Newton iterations, Jacobians) of ours and of the plain run, load-independent; "
          "rows in C = rows the loop ran in "
          "tbn_track_rows; restarts/carried = the tracked twin's integrator re-initialisations and carried "
          "changes; TRACKINGBOX_NATIVE=0 runs the twins on the Python path)")
    print(f"\n{'bench':16s} {'stops/sample':>12s} {'plain RHS':>9s} {'stops RHS':>9s} {'ours RHS':>9s} "
          f"{'stops/plain':>11s} {'ours/stops':>10s} {'stops integrator CPU':>20s} {'floor/plain':>11s} "
          f"{'floor/bound':>11s}")
    for r in rows:
        if r["plain_rhs"] > 0 and r["stops_rhs"] > 0:
            floor = exact_timing_floor(r)
            print(f"{r['bench']:16s} {r['substeps']:12d} {r['plain_rhs']:9d} {r['stops_rhs']:9d} {r['rhs']:9d} "
                  f"{r['stops_rhs'] / r['plain_rhs']:11.2f} {r['rhs'] / r['stops_rhs']:10.2f} "
                  f"{r['stops_in_c']:20.3f} {floor / r['plain_cpu']:11.2f} {floor / r['bound_cpu']:11.2f}")
    print("(stops = the plain twin run stopped exactly at every sample and sub-step, as the tracked twin is, with no "
          "parameter changed: what the discrete mode's exact timing of the controllers' moves costs the integrator "
          "before any move; ours/stops = what the moves, restarts and controllers add on top; floor = the stops "
          "run's integrator CPU plus the plain run's CPU outside its integrator: the least any tracking run that "
          "keeps the exact timing could cost in CPU, were its moves free and its Python as lean as the plain "
          "run's; floor/plain and floor/bound against the targets 1.5 and 2)")
    print("\nboth controller modes, from this run (same plain and bound): discrete = the default (the controllers' "
          "exact discretisation, updated every sample and sub-step); continuous = controllers='continuous' (the box's "
          "laws integrated with the twin by CVODE in C, on the inputs twin)")
    print(f"{'bench':16s} {'mode':10s} {'ours wall':>9s} {'ours CPU':>8s} {'ours/plain':>10s} {'ours/bound':>10s} "
          f"{'CPU ours/plain':>14s} {'CPU ours/bound':>14s} {'integrator CPU':>14s} {'restarts':>8s} {'RHS':>9s}")
    for r in rows:
        c = r["continuous"]
        modes = [("discrete", r["wall"], r["cpu"], r["in_c"], r["restarts"], r["rhs"])]
        if not c.get("reason"):
            modes.append(("continuous", c["wall"], c["cpu"], c["in_c"], c["restarts"], c["rhs"]))
        for mode, wall, cpu, in_c, restarts, rhs in modes:
            print(f"{r['bench']:16s} {mode:10s} {wall:9.2f} {cpu:8.2f} {wall / r['plain_wall']:10.2f} "
                  f"{wall / r['bound_wall']:10.2f} {cpu / r['plain_cpu']:14.2f} {cpu / r['bound_cpu']:14.2f} "
                  f"{in_c:14.3f} {restarts:8d} {rhs:9d}")
        if c.get("reason"):
            print(f"  ({r['bench']}: no continuous run: {c['reason']})")
        else:
            print(f"  ({r['bench']}: inputs twin ready in {c['compile_wall']:.1f} s before the continuous run: a "
                  "compile on a cold cache, a lookup on a warm one)")
    print("(targets: ours/plain <= 1.5, ours/bound <= 2; integrator CPU = CPU inside the native C calls; restarts "
          "= CVODE (re-)initialisations of the tracked twin)")
    for r in rows:
        if r["states"]:
            print(f"note: {r['bench']} has state compensation: plain and bound run with its corrections at 0")
    failed = False
    if memory:
        print("\nmemory: peak RSS of one `trackingbox track` child process per run length (same pairs)")
        print(f"{'bench':16s} {'days':>5s} {'rows':>7s} {'peak RSS MiB':>12s} {'wall s':>7s} {'CPU s':>7s}")
        for name, d, rss, wall, n, cpu in memory:
            print(f"{name:16s} {d:5g} {n:7d} {rss / 1024:12.1f} {wall:7.0f} {cpu:7.1f}")
        for name in mem_benches:
            runs = sorted((d, rss) for b, d, rss, *_ in memory if b == name)
            if len(runs) < 2:
                continue
            (d0, r0), (d1, r1) = runs[0], runs[-1]
            growth = (r1 - r0) / 1024
            print(f"{name}: growth {d0:g} d -> {d1:g} d: {growth:+.1f} MiB "
                  f"({growth / (d1 - d0):+.2f} MiB per extra day); allowed: +{args.memory_allowance:g} MiB")
            if growth > args.memory_allowance:
                print(f"FAIL: {name}: the {d1:g}-day run's peak ({r1 / 1024:.1f} MiB) exceeds the {d0:g}-day run's "
                      f"({r0 / 1024:.1f} MiB) by more than {args.memory_allowance:g} MiB")
                failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
