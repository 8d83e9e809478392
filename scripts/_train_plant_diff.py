#!/usr/bin/env python3
"""The size of a hidden effect on each tag: two plant FMUs of ``bench evaporator-train`` on the same inputs.

Runs a hidden case's ``plant.fmu`` and the ``clean`` case's (same seed, effects and hours, so the same
``plant_inputs.csv``) noise-free from the first sample up to ``--stop`` seconds (before the first
stoppage: the plants' hold inputs are not driven here) and prints per output the mean, smallest and
largest difference (effect - clean) after ``--skip`` seconds. Compare with each tag's sensor noise
(``diagnose.json``'s ``where``).

Example::

    scripts/train_plant_diff CASE_DIR CLEAN_DIR --stop 28000 \\
        --outputs "PI_steamChest[1],ZI_body[2]"
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case", type=Path, help="the hidden case's folder (plant.fmu, plant_inputs.csv)")
    ap.add_argument("clean", type=Path, help="the clean case's folder (same seed, effects, hours)")
    ap.add_argument("--stop", type=float, default=28000.0, help="end of the run, s from the first sample")
    ap.add_argument("--skip", type=float, default=3600.0, help="seconds left out at the start")
    ap.add_argument("--outputs", required=True, help="comma-separated plant variables")
    args = ap.parse_args(argv)
    inputs = np.genfromtxt(args.case / "plant_inputs.csv", delimiter=",", names=True)
    clean_inputs = np.genfromtxt(args.clean / "plant_inputs.csv", delimiter=",", names=True)
    if not all(np.allclose(inputs[n], clean_inputs[n]) for n in inputs.dtype.names):
        raise SystemExit("the two cases' plant inputs differ: build them with the same seed, effects and hours")
    outputs = args.outputs.split(",")
    runs = [simulate_fmu(str(d / "plant.fmu"), stop_time=args.stop, input=inputs, output=outputs,
                         output_interval=60.0) for d in (args.case, args.clean)]
    kept = runs[0]["time"] > args.skip
    for name in outputs:
        diff = (runs[0][name] - runs[1][name])[kept]
        print(f"{name:24s} mean {np.mean(diff):+.4g}  min {diff.min():+.4g}  max {diff.max():+.4g}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
