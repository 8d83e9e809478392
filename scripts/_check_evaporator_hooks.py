#!/usr/bin/env python3
"""Check (not a test): the evaporator bench's Twin and Plant with the diagnosis hooks off against a git ref's.

Compiles ``Benches.Evaporator.Twin`` and ``Plant`` from this checkout and from ``--ref``'s
``modelica/`` (``git archive``), runs each 4 h through the same inputs (the nominal point
with slow sinusoidal moves of 3 % and a 33 min stoppage) and prints, per model, the largest
difference over every output relative to its magnitude. 0.0 means the hooks, off, leave
the equations the compiler builds unchanged.

    scripts/check_evaporator_hooks --ref main
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

import numpy as np
import pandas as pd

from trackingbox.benches.evaporator import NOMINAL
from trackingbox.compiler import compile_model, library_path
from trackingbox.fmu import FMUModel

MODELS = ("TrackingBox.Benches.Evaporator.Twin", "TrackingBox.Benches.Evaporator.Plant")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ref", default="main", help="git ref to compare with (default main)")
    args = ap.parse_args(argv)
    root = Path(__file__).resolve().parents[1]
    t = np.arange(0, 4 * 3600.0 + 1, 600.0)
    inputs = pd.DataFrame({"time": t, **{k: v * (1 + 0.03 * np.sin(t / 2000.0 + i))
                                         for i, (k, v) in enumerate(NOMINAL.items())}})
    inputs.loc[(t > 5000) & (t < 7000), "feedFlowSet"] = 0.02
    worst_all = 0.0
    with tempfile.TemporaryDirectory(prefix="hooks-") as tmp:
        work = Path(tmp)
        archive = subprocess.run(["git", "-C", str(root), "archive", args.ref, "modelica"], check=True,
                                 capture_output=True).stdout
        with tarfile.open(fileobj=BytesIO(archive)) as tar:
            tar.extractall(work / "ref", filter="data")
        for model in MODELS:
            runs = []
            for name, lib in ((args.ref, work / "ref" / "modelica" / "TrackingBox"), ("here", Path(library_path()))):
                fmu = work / f"{name.replace('/', '_')}-{model.rsplit('.', 1)[1]}.fmu"
                compile_model(lib, model, backend="embedded", output=fmu)
                with FMUModel(fmu) as m:
                    outs = [v.name for v in m.info.variables if v.causality == "output"]
                    runs.append(m.simulate(stop_time=4 * 3600.0, output_interval=10.0, inputs=inputs, outputs=outs))
            a, b = runs
            diffs = {c: float(np.max(np.abs(a[c] - b[c])) / max(1.0, float(np.abs(a[c]).max())))
                     for c in a.columns if c != "time"}
            name, worst = max(diffs.items(), key=lambda kv: kv[1])
            worst_all = max(worst_all, worst)
            print(f"{model}: {len(diffs)} outputs, largest relative difference {worst:.3g} ({name})")
    return 0 if worst_all == 0.0 else 1


if __name__ == "__main__":
    sys.exit(main())
