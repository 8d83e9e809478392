"""Why the MSL harness called Modelica.Fluid.Examples.PumpingSystem 'close' before ``close54`` (issue 35): when its
on/off controller switches the pump, in the reference and in ours at several tolerances.

    scripts/check_pumping_switches FMU [--tolerances 1e-7,1e-8,1e-10]

FMU: ``trackingbox compile <MSL>/Modelica --model Modelica.Fluid.Examples.PumpingSystem --backend embedded -o FMU``.

The controller switches when the reservoir's relative pressure, falling at about 7 Pa/s, crosses its band; the
pump's speed (``PumpRPMGenerator.y``, a TriggeredTrapezoid of 1200 rpm, rising and falling over 3 s) then ramps
at 400 rpm/s. A ramp's start is read back from the first output point on it (the 0.001 rpm offset included).
Printed: each ramp's start in the reference, ours minus it (ms) per tolerance, the reservoir level's difference
from the tightest run just before the first switch, and the harness's deviation of each run."""
from __future__ import annotations

import argparse
from pathlib import Path

import fmpy
import numpy as np

from trackingbox.compiler import msl_harness as h

MODEL = "Modelica.Fluid.Examples.PumpingSystem"
RATE, TOP, FLOOR = 400.0, 1200.001, 0.001


def ramp_starts(t: np.ndarray, y: np.ndarray) -> list[tuple[str, float]]:
    """(direction, start time) of each ramp of the speed, from the first output point on it."""
    on = (y > FLOOR + 1.0) & (y < TOP - 1.0)
    out = []
    for j in np.flatnonzero(on[1:] & ~on[:-1]) + 1:
        up = j + 1 < y.size and y[j + 1] > y[j]
        out.append(("up", t[j] - (y[j] - FLOOR) / RATE) if up else ("down", t[j] - (TOP - y[j]) / RATE))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("fmu", type=Path)
    ap.add_argument("--tolerances", default="1e-7,1e-8,1e-10")
    args = ap.parse_args()
    ref = h.load_reference(h.default_reference(), MODEL)
    if ref is None:
        raise SystemExit(f"no reference for {MODEL} under {h.default_reference()}")
    steps = np.diff(ref.time)
    interval = float(np.median(steps[steps > 0]))
    starts = ramp_starts(ref.time, ref.values["PumpRPMGenerator.y"])
    print("reference's ramps start at " + ", ".join(f"{d} {s:.5f} s" for d, s in starts))
    runs = {}
    for tol in (float(x) for x in args.tolerances.split(",")):
        with h._cvode_steps(h.CVODE_MAX_STEPS):
            r = fmpy.simulate_fmu(str(args.fmu), start_time=0.0, stop_time=float(ref.time[-1]),
                                  relative_tolerance=tol, output_interval=interval, output=list(ref.signals),
                                  fmi_type="ModelExchange")
        runs[tol] = (np.asarray(r["time"], float), {s: np.asarray(r[s], float) for s in ref.signals})
    tight = runs[min(runs)]
    first = starts[0][1] - 1.0
    for tol, (t, v) in runs.items():
        ours = ramp_starts(t, v["PumpRPMGenerator.y"])
        shifts = ", ".join(f"{(o - s) * 1e3:+.2f}" for (_, o), (_, s) in zip(ours, starts))
        level = np.interp(first, t, v["reservoir.level"]) - np.interp(first, tight[0], tight[1]["reservoir.level"])
        worst, where, _ = h.compare(ref, t, v)
        print(f"rtol {tol:g}: {len(ours)} ramps, ours minus the reference's start (ms): {shifts}; reservoir level "
              f"minus the rtol {min(runs):g} run's at {first:.1f} s: {level:+.2e} m; harness deviation {worst:.3g} "
              f"on {where}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
