#!/usr/bin/env python3
"""Where a trend in the evaporator's product DS residual (QI-6150) comes from (not a test).

For a case folder written by ``scripts/bench_diagnose --bench evaporator`` (``diagnose.json`` beside
it: the null fit is read from there, not refitted) this splits the null model's QI-6150 residual
``measured - twin`` into ``measured - plant`` (the measurement chain: sensor noise, the historian's
dead band and heartbeat) and ``plant - twin`` (the twin's baseline, its fouling moving in time as the
null lets it), the plant's noise-free output coming from ``plant.fmu`` run again on
``plant_inputs.csv`` (the warm-up held at the first inputs, as the bench's scenario holds them).
Per window: offset and slope of a straight line through each; the slope of the measured *records*
(exception-reported, not the grid) minus the plant, with its standard error from those records; the
null's fouling against the plant's (``truth.json``); the null twin's QI-6150 sensitivity to it.
``--seeds`` writes the ``clean`` case again with other seeds under ``--work`` and gives the records'
slope for each (noise draws of the same meter).

    scripts/evaporator_meter_trend out/bench-diagnose/evaporator/clean-x1-s0
    scripts/evaporator_meter_trend out/bench-diagnose/evaporator/clean-x1-s0 --seeds 1,2,3
"""
from __future__ import annotations

import argparse
import importlib
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

from trackingbox.benches import make_bench
from trackingbox.simulation.models import close_models, open_model
from trackingbox.spec import load_spec

TAG, PLANT_VAR, WARMUP = "QI-6150", "DI_product", 3 * 3600.0


def plant_output(case: Path) -> tuple[np.ndarray, np.ndarray]:
    """The plant's noise-free product DS reading on the measured clock (s from the first sample)."""
    pin = pd.read_csv(case / "plant_inputs.csv")
    first = pin.iloc[0]
    warm = pd.DataFrame({"time": np.arange(0.0, WARMUP, 10.0), **{c: first[c] for c in pin.columns if c != "time"}})
    frame = pd.concat([warm, pin.assign(time=pin["time"] + WARMUP)], ignore_index=True)
    model = open_model(case / "plant.fmu")
    try:
        res = model.simulate(stop_time=float(frame["time"].iloc[-1]), output_interval=10.0, inputs=frame,
                             outputs=[PLANT_VAR])
    finally:
        model.close()
    return res["time"].to_numpy() - WARMUP, res[PLANT_VAR].to_numpy()


def line(t: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Offset, slope (per hour) and the slope's standard error of a straight line through the finite samples."""
    ok = np.isfinite(y)
    tc = (t[ok] - t[ok].mean()) / 3600.0
    a = np.c_[np.ones(ok.sum()), tc]
    c, *_ = np.linalg.lstsq(a, y[ok], rcond=None)
    e = y[ok] - a @ c
    return float(c[0]), float(c[1]), float(np.sqrt(e @ e / max(ok.sum() - 2, 1) / (tc @ tc)))


def records_slope(case: Path, pt: np.ndarray, py: np.ndarray, windows: dict) -> None:
    m = pd.read_csv(case / "measurements.csv")
    m = m[m["tag"] == TAG]
    start = pd.Timestamp(json.loads((case / "truth.json").read_text())["start"])   # the data's first sample
    t = (pd.to_datetime(m["time"], format="ISO8601") - start).dt.total_seconds().to_numpy()
    v = pd.to_numeric(m["value"], errors="coerce").to_numpy()
    r = v - np.interp(t, pt, py)
    for name, (a, b) in windows.items():
        k = (t >= a) & (t <= b)
        _, slope, se = line(t[k], r[k])
        print(f"  {name:10s} records - plant: {int(np.isfinite(r[k]).sum())} records, slope {slope:+.3g} /h "
              f"(se {se:.2g}, {slope / se:+.2f} se)")


def null_split(case: Path, pt: np.ndarray, py: np.ndarray) -> None:
    residuals = importlib.import_module("trackingbox.diagnose.residuals")
    spec = load_spec(case / "spec.toml")
    null = SimpleNamespace(parameters=json.loads((case / "diagnose.json").read_text())["null"]["parameters"])
    truth = json.loads((case / "truth.json").read_text())["trajectories"]["effect.Rf"]
    try:
        w = residuals.where(spec, null=null)
    finally:
        close_models()
    i = list(w.problem.names).index("effect.Rf")
    for s, jac in ((w.training, w.jacobian[0]), (w.validation, w.jacobian[1])):
        plant = np.interp(s.time, pt, py)
        meas, twin = s.measured[TAG], s.simulated[TAG]
        for label, y in (("measured - twin", meas - twin), ("measured - plant", meas - plant),
                         ("plant - twin", np.where(np.isfinite(meas), plant - twin, np.nan))):
            off, slope, _ = line(s.time, y)
            print(f"  {s.name:10s} {label:17s} offset {off:+.3g}, slope {slope:+.3g} /h (grid)")
        print(f"  {s.name:10s} d{TAG}/dRf of the null twin: mean {np.nanmean(jac[TAG][:, i]):.4g}")
    rf = np.interp(w.training.time, truth["time"], truth["value"])
    print(f"  plant's fouling over training: {rf[0]:.3g} -> {rf[-1]:.3g} m2.K/W (null fit {null.parameters['effect.Rf']:.3g})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case", type=Path, help="a case folder of scripts/bench_diagnose (with diagnose.json)")
    ap.add_argument("--seeds", default="", help="comma-separated seeds of further clean cases (records only)")
    ap.add_argument("--work", type=Path, default=Path("out/meter-trend"), help="where those cases are written")
    args = ap.parse_args()
    spec = load_spec(args.case / "spec.toml")
    windows = {k: tuple(v) for k, v in spec.windows.items()}
    pt, py = plant_output(args.case)
    print(f"{args.case}:")
    records_slope(args.case, pt, py, windows)
    null_split(args.case, pt, py)
    twin = args.case / "twin.fmu"
    for seed in [int(s) for s in args.seeds.split(",") if s]:
        case = args.work / f"clean-s{seed}"
        if not (case / "truth.json").is_file():
            make_bench("evaporator", case, seed=seed, hours=24, twin_fmu=twin, hidden="clean")
        print(f"{case} (seed {seed}):")
        records_slope(case, *plant_output(case), windows)


if __name__ == "__main__":
    main()
