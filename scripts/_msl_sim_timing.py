#!/usr/bin/env python3
"""Benchmark (not a test): where an MSL example's FMU spends its simulation, as ``scripts/msl`` simulates it.

Simulates FMU with the harness's own ``simulate`` (the reference's output grid and tolerance, fmpy's
CVODE) and times each output point through fmpy's ``step_finished``: the CPU seconds up to the first
output point (initialisation and the first step), the CPU seconds per output point after it, and the
FMI calls by name (fmpy's call logger). ``--limit`` stops the simulation after that many CPU seconds
(the figures then cover the points reached); the comparison with the reference is printed where the
whole experiment ran.

Examples::

    scripts/msl_sim_timing MomentumBalanceFittings.fmu Modelica.Fluid.Examples.Explanatory.MomentumBalanceFittings
    scripts/msl_sim_timing PumpingSystem.fmu Modelica.Fluid.Examples.PumpingSystem --limit 200
"""
from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("fmu", type=Path)
    ap.add_argument("model", help="the example's full name (finds its reference results)")
    ap.add_argument("--reference", type=Path, default=None, help="reference results root (default: ../shared/msl-reference)")
    ap.add_argument("--limit", type=float, default=float("inf"), help="stop after this many CPU seconds")
    args = ap.parse_args()
    if not args.fmu.exists():
        print(f"error: no FMU at {args.fmu}", file=sys.stderr)
        return 2
    import fmpy
    from trackingbox.compiler import msl_harness as h

    ref = h.load_reference(args.reference or h.default_reference(), args.model)
    calls: collections.Counter[str] = collections.Counter()
    marks: list[tuple[float, float, float, int]] = []
    t0w, t0c = time.perf_counter(), time.process_time()

    def step(t, *_):
        marks.append((t, time.perf_counter() - t0w, time.process_time() - t0c, sum(calls.values())))
        if len(marks) % 500 == 1:
            print("progress t=%g wall %.1f cpu %.1f calls %d" % marks[-1], flush=True)
        return time.process_time() - t0c < args.limit

    original = fmpy.simulate_fmu

    def timed(*a, **k):
        k["step_finished"] = step
        k["fmi_call_logger"] = lambda msg: calls.update([msg.split("(")[0].strip()])
        return original(*a, **k)

    fmpy.simulate_fmu = timed
    errors: list[str] = []
    try:
        tt, values, problem = h.simulate(args.fmu, ref, errors)
        print("problem:", problem or "none")
        if ref is not None and not problem:
            print("compare:", h.compare(ref, tt, values))
    except Exception as exc:  # noqa: BLE001 - fmpy raises plain exceptions for FMU failures
        print("simulation failed:", type(exc).__name__, str(exc)[:300], errors[-2:])
    finally:
        fmpy.simulate_fmu = original
    print(f"total: wall {time.perf_counter() - t0w:.1f} s, cpu {time.process_time() - t0c:.1f} s")
    if marks:
        t, w, c, n = marks[0]
        print(f"first output point t = {t:g}: wall {w:.1f} s, cpu {c:.1f} s, {n} FMI calls")
        t2, w2, c2, n2 = marks[-1]
        k = max(len(marks) - 1, 1)
        print(f"last output point t = {t2:g} ({len(marks) - 1} points after the first): cpu {(c2 - c) / k * 1e3:.2f} ms "
              f"and {(n2 - n) / k:.1f} FMI calls per point")
    print("FMI calls:", calls.most_common(12))
    return 0


if __name__ == "__main__":
    sys.exit(main())
