#!/usr/bin/env python3
"""The scale of a ``burkeite-scale`` case: the plant's, and the fitted ``soluble-scale`` twin's, carried.

Evidence for docs/diagnose-effects.md ("A state carried through the history"), not a test. For a case
folder written by ``scripts/bench_diagnose --bench evaporator --cases burkeite-scale`` (after its
``diagnose.json``), it

* re-runs the case's plant (``make_bench`` with the case's seed, hours and FMUs, into a temporary
  folder) recording its scale ``Rs``, its fouling ``effect.Rf`` and the effect's dry solids ``effect.x``;
* runs the patched twin of the ``soluble-scale@effect`` candidate (``diagnose/work/soluble-scale-effect``)
  at the spec's candidates' warm start and the effect's fitted values (``diagnose.json``) over both
  windows, its scale ``R`` carried from the training run into the validation run, and once more with
  the scale settled at each run's steady start (no carry: before);

and prints the scales at the hours given.

Example::

    scripts/evaporator_scale_trace out/bench-diagnose/evaporator/burkeite-scale-x1-s0
"""
from __future__ import annotations

import argparse
import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

import trackingbox.benches.evaporator as ev
from trackingbox.benches import make_bench
from trackingbox.simulation.models import close_models
from trackingbox.simulation.windows import load_windows, problem_from_spec, simulate_window
from trackingbox.spec import load_spec


def plant(case: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    truth = json.loads((case / "truth.json").read_text())
    ev.TRAJECTORIES = {**ev.TRAJECTORIES, "Rs": "Rs", "effect.x": "effect.x"}
    with tempfile.TemporaryDirectory() as tmp:
        make_bench("evaporator", tmp, seed=int(truth["seed"]), hours=float(truth["hours"]),
                   plant_fmu=case / "plant.fmu", twin_fmu=case / "twin.fmu", hidden=truth["hidden"]["case"],
                   noise_scale=float(truth["noise_scale"]))
        runs = json.loads((Path(tmp) / "truth.json").read_text())["trajectories"]
    return {k: (np.array(v["time"]), np.array(v["value"])) for k, v in runs.items()}


def twin(case: Path, warmup: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    found = json.loads((case / "diagnose.json").read_text())
    fitted = next(c["values"] for c in found["candidates"]
                  if c["effect"] == "soluble-scale" and c["target"] == "effect")
    spec = load_spec(case / "diagnose" / "work" / "soluble-scale-effect" / "spec.toml")
    problem = problem_from_spec(spec, warmup=warmup)
    windows = load_windows(spec, warmup=problem.warmup)
    x = np.array([fitted.get(n.removeprefix("solubleScale_effect_"), s) for n, s in zip(problem.names, problem.start)])
    probe = replace(problem, outputs={**problem.outputs, "__R": "solubleScale_effect_R"})
    out = {}
    try:
        for label, p in (("carried", probe), ("settled", replace(probe, carry=()))):
            for w in windows:
                out[f"{label} {w.name}"] = (w.time, simulate_window(p, w, x, history=windows)["__R"])
    finally:
        close_models()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", type=Path)
    ap.add_argument("--hours", default="0,9,12,14,16,18,20,22,24", help="times to print (h)")
    ap.add_argument("--warmup", type=float, default=3 * 3600.0, help="warm-up before each window (s), diagnose's")
    args = ap.parse_args()
    series = {**plant(args.case), **twin(args.case, args.warmup)}
    names = list(series)
    print("hour  " + "  ".join(f"{n:>18}" for n in names))
    for h in (float(v) for v in args.hours.split(",")):
        row = []
        for n in names:
            t, v = series[n]
            row.append(f"{np.interp(h * 3600.0, t, v):18.3e}" if t[0] <= h * 3600.0 <= t[-1] else f"{'':>18}")
        print(f"{h:4g}  " + "  ".join(row))


if __name__ == "__main__":
    main()
