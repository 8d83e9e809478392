#!/usr/bin/env python3
"""Benchmark: estimation on the 24 h heat-production bench, measured against what can be removed.

Fourteen parameters, the CLI's default budget. The twin's pipe and pump
curves are linear where the plant's are quadratic, so even the plant's true
values leave an error: the estimator can only remove the part of the start
values' error that the true values do not have. Per output tag, on the
held-out validation window, the script prints the NRMSE

* ``initial``: at the spec's start values (the twin before estimation),
* ``estimated``: at the estimate,
* ``at truth``: at the plant's true values (``truth.json``; the twin's
  structure, the plant's numbers),
* ``noise floor``: the sensor's noise over the tag's range (``benches.base.NOISE``),
  what a perfect model would score.

A tag counts when its initial error is above twice its noise floor and the
true values would lower it (``initial > at truth``): there is error to remove.
The criterion is the share of the removable error removed over those tags,

``sum(initial - estimated) / sum(initial - at truth) >= 60 %``.

Exits 1 when the criterion fails (a failing benchmark is a defect), 2 on a
usage or pipeline error. Runs for about 20 min on an idle 2-core machine.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: The criterion: share of the removable validation error that the estimate removes.
MIN_SHARE = 0.60
#: A tag counts when its initial NRMSE is above this multiple of its noise floor.
FLOOR_FACTOR = 2.0


def noise_floor(sensor, measured: np.ndarray) -> float:
    """NRMSE that the sensor's noise alone gives on *measured* (the score of a perfect model)."""
    from trackingbox.estimation.objective import scale as _scale

    ok = np.isfinite(measured)
    if not ok.any():
        return math.nan
    sigma, relative = sensor.noise
    if relative:
        sigma = sigma * float(np.sqrt(np.mean(measured[ok] ** 2)))
    return float(sigma / _scale(measured[ok]))


def judge(initial: dict[str, float], estimated: dict[str, float], truth: dict[str, float],
          floor: dict[str, float]) -> tuple[float, list[str], list[tuple[str, str]]]:
    """Share of the removable error removed; the tags counted; the tags left out with the reason."""
    counted, left = [], []
    for tag in initial:
        if not initial[tag] > FLOOR_FACTOR * floor[tag]:
            left.append((tag, f"initial {initial[tag]:.4g} within {FLOOR_FACTOR:g} x its noise floor {floor[tag]:.4g}"))
        elif not initial[tag] > truth[tag]:
            left.append((tag, f"the true values do not lower it ({initial[tag]:.4g} -> {truth[tag]:.4g})"))
        else:
            counted.append(tag)
    removable = sum(initial[t] - truth[t] for t in counted)
    removed = sum(initial[t] - estimated[t] for t in counted)
    return (removed / removable if removable > 0 else math.nan), counted, left


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="bench_heat_production", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=None, help="folder for the bench case (default: temporary)")
    ap.add_argument("--seed", type=int, default=0, help="bench noise and estimator seed (default 0)")
    ap.add_argument("--workers", type=int, default=2, help="parallel simulations (default 2)")
    ap.add_argument("--hours", type=float, default=None, help="hours of data (default: the bench's 24)")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = ap.parse_args(argv)

    from trackingbox.benches import make_bench
    from trackingbox.benches.heat_production import DEFINITION
    from trackingbox.errors import TrackingError
    from trackingbox.estimation import Objective, estimate, load_windows, problem_from_spec
    from trackingbox.spec import load_spec

    with tempfile.TemporaryDirectory(prefix="bench-hp-") as tmp:
        out = args.out if args.out is not None else Path(tmp)
        wall0 = time.perf_counter()
        try:
            case = make_bench("heat-production", out / "hp", seed=args.seed, hours=args.hours)
            spec = load_spec(case.spec)
            result = estimate(spec, seed=args.seed, workers=args.workers)
            problem = problem_from_spec(spec)
            validation = load_windows(spec)[1]
            truth_x = np.array([case.truth[name] for name in problem.names])
            at_truth = Objective(problem, validation).nrmse(truth_x)
        except TrackingError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        seconds = time.perf_counter() - wall0

    sensors = {s.tag: s for s in DEFINITION.outputs}
    floor = {tag: noise_floor(sensors[tag], np.asarray(validation.measured[tag], float))
             for tag in result.validation_nrmse_initial}
    initial, estimated = dict(result.validation_nrmse_initial), dict(result.validation_nrmse)
    share, counted, left = judge(initial, estimated, at_truth, floor)
    ok = math.isfinite(share) and share >= MIN_SHARE
    if args.json:
        print(json.dumps({
            "tags": {t: {"initial": initial[t], "estimated": estimated[t], "at_truth": at_truth[t],
                         "noise_floor": floor[t], "counted": t in counted} for t in initial},
            "left_out": dict(left), "share_removed": share, "min_share": MIN_SHARE, "passed": ok,
            "parameters": result.parameters, "truth": {n: case.truth[n] for n in problem.names},
            "seconds": seconds}, indent=1))
    else:
        print("validation NRMSE per tag (held-out window)")
        print(f"{'tag':8s} {'initial':>9s} {'estimated':>10s} {'at truth':>9s} {'noise floor':>12s}  counted")
        for t in initial:
            print(f"{t:8s} {initial[t]:9.4g} {estimated[t]:10.4g} {at_truth[t]:9.4g} {floor[t]:12.4g}  "
                  f"{'yes' if t in counted else 'no'}")
        for t, why in left:
            print(f"  {t} not counted: {why}")
        print(f"{'PASS' if ok else 'FAIL'}  share of the removable error removed over {len(counted)} tags: "
              f"{share:.1%} (needs {MIN_SHARE:.0%}): sum(initial - estimated) / sum(initial - at truth)")
        print(f"{'all criteria met' if ok else 'FAILED'} in {seconds:.0f} s")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
