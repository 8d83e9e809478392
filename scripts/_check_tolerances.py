"""Whether an MSL example's deviation from its reference is the integrator's (issue 35: ``ThreeTanks``
is close, 1.16e-3 of ``tank3.medium.T``'s range): the compiled FMU simulated on the reference's output
grid at several relative tolerances, each signal's deviation from the reference as the harness computes
it, and how far each run is from the tightest one.

    scripts/check_tolerances FMU MODEL [--tolerances 1e-6,1e-8,1e-10]

FMU: ``trackingbox compile <MSL>/Modelica --model MODEL --backend embedded -o FMU``."""
from __future__ import annotations

import argparse
from pathlib import Path

import fmpy
import numpy as np

from trackingbox.compiler import msl_harness as h


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("fmu", type=Path)
    ap.add_argument("model")
    ap.add_argument("--tolerances", default="1e-6,1e-8,1e-10")
    args = ap.parse_args()
    ref = h.load_reference(h.default_reference(), args.model)
    if ref is None:
        raise SystemExit(f"no reference for {args.model} under {h.default_reference()}")
    steps = np.diff(ref.time)
    interval = float(np.median(steps[steps > 0]))
    window = h.WINDOW * float(ref.time[-1] - ref.time[0])
    runs = {}
    for tol in (float(t) for t in args.tolerances.split(",")):
        with h._cvode_steps(h.CVODE_MAX_STEPS):
            r = fmpy.simulate_fmu(str(args.fmu), start_time=float(ref.time[0]), stop_time=float(ref.time[-1]),
                                  relative_tolerance=tol, output_interval=interval, output=list(ref.signals),
                                  fmi_type="ModelExchange")
        t = np.asarray(r["time"], float)
        runs[tol] = (t, {s: np.asarray(r[s], float) for s in ref.signals})
        devs = {s: h.deviation(ref.time, ref.values[s], t, runs[tol][1][s], window, ref.tolerance) for s in ref.signals}
        print(f"rtol {tol:g}: deviation from the reference / range: "
              + ", ".join(f"{s} {d:.3g}" for s, d in devs.items()))
    tight = min(runs)
    t0, v0 = runs[tight]
    for tol, (t, v) in runs.items():
        if tol != tight:
            print(f"rtol {tol:g}: largest distance from rtol {tight:g}: "
                  + ", ".join(f"{s} {np.max(np.abs(np.interp(t0, t, v[s]) - v0[s])):.3g}" for s in ref.signals))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
