"""Where the tracked parameters' slow errors come from on the evaporator's twin-structure plant (issue 31).

A diagnostic (not a test) of the ``bands-evaporator-plain`` runs that ``scripts/bench_uncertainty`` leaves in
``OUT/cases``. Per seed it replays the twin (``_bench_apply._replay``: every pair's parameter forced to the
plant's truth, the Python rows) three ways, reused when on disk under ``CASE/explain``:

* ``A``: as tracked (measured inputs, the held parameters at their estimates, the levels' state compensation);
* ``C``: the plant's true inputs every sample (no noise, no historian) and the held parameters at the plant's
  values: what is left is the paired tags' own measurement and the state compensation;
* ``D``: ``C`` without the state compensation of levels (the twin's own level controllers alone).

The error each replay reads on a paired tag (measured - tracked) is what no loop on it can remove. Then the three
loops, linearised as :func:`trackingbox.identify.bands.loops_noise` takes them (each tag follows every parameter
through the gain matrix with its pair's first-order lag, each parameter its own PI law, frozen in the rows its
pair holds), are driven by ``A``'s errors and by the truth's motion, and the result is checked against the run's
misses (truth - p; correlation, rms after 12 h), then split by driver: the truth's motion alone (the lag part's
job) and each tag's error at the truth alone (the noise part's job). Each tag's share is set against what the
band's noise part gives it (``loops_noise``'s autocorrelations with the tag's fast-error autocovariance, as
:class:`~trackingbox.identify.bands.BandTracker`), and the tag's error spectrum (Welch, 45 h segments) against
the white level that autocovariance implies.

    scripts/explain_evaporator_bands --out DIR [--seeds 3] [--first 0]     (DIR: bench_uncertainty's --out)
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

#: rows after this (s) are scored, as bench_uncertainty's bands-evaporator cases
AFTER = 12 * 3600.0
#: the fast error's centring window (samples of 10 s): 30 min, as the band's noise statistics
CENTRE = 180


def replays(case: Path) -> dict[str, Any]:
    """The replays A, C and D of *case* (module docstring) as DataFrames, run where not on disk."""
    import pandas as pd

    from _bench_apply import _replay
    from trackingbox.spec import load_spec

    truth = json.loads((case / "truth.json").read_text())
    spec = load_spec(case / "spec.toml")
    out = case / "explain"
    out.mkdir(exist_ok=True)
    held = {k: truth["parameters"][k] for k in ("inletValve.KvMax", "pump.VMax") if k in truth["parameters"]}
    if "effect.dBPR" in spec.fixed:  # the plain plant's dBPR is off: the twin's effect.dBPR is 0 there
        held["effect.dBPR"] = 0.0
    meas = out / "measurements_true_inputs.csv"
    if not meas.exists():
        m = pd.read_csv(case / "measurements.csv")
        pi = pd.read_csv(case / "plant_inputs.csv")
        start = pd.Timestamp(truth["historian"]["start"])
        stamps = (start + pd.to_timedelta(pi["time"], unit="s")).dt.strftime("%Y-%m-%dT%H:%M:%S.%f").str[:-3]
        rows = [pd.DataFrame({"tag": tag, "time": stamps + "+00:00", "value": pi[var]})
                for tag, var in spec.inputs.items()]
        pd.concat([m[~m["tag"].isin(list(spec.inputs))], *rows]).to_csv(meas, index=False)
    true_inputs = dataclasses.replace(spec, measurements=meas)
    return {"A": _replay(spec, truth, out / "A", {}, "evaporator"),
            "C": _replay(true_inputs, truth, out / "C", held, "evaporator"),
            "D": _replay(dataclasses.replace(true_inputs, states=()), truth, out / "D", held, "evaporator")}


def simulate(gains: np.ndarray, loops: list[tuple[float, float, float, float]], ts: float, drive: np.ndarray,
             truth_step: np.ndarray, hold: np.ndarray, start_error: np.ndarray) -> np.ndarray:
    """``truth - p`` per row of the linearised loops (module docstring): *drive* ``(rows, pairs)`` the error each
    tag reads at the truth, *truth_step* ``(rows, pairs)`` the truth's change to the next row, *hold* the rows
    each pair holds, *start_error* ``p - truth`` at row 0; *loops* per pair ``(gain, time_constant, kc, ti)``."""
    sign = np.array([1.0 if lp[0] > 0 else -1.0 for lp in loops])
    a = np.array([math.exp(-ts / lp[1]) if lp[1] > 0 else 0.0 for lp in loops])
    kc = np.array([lp[2] for lp in loops])
    ti = np.array([lp[3] for lp in loops])
    d = np.array(start_error, dtype=float)
    z = gains @ d
    e_prev = np.full(d.size, np.nan)
    out = np.empty_like(drive)
    for k in range(drive.shape[0]):
        e = drive[k] - z
        for j in range(d.size):
            if hold[k, j]:
                e_prev[j] = np.nan  # frozen; resumes without a proportional kick
                continue
            ep = e[j] if math.isnan(e_prev[j]) else e_prev[j]
            d[j] += sign[j] * kc[j] * ((e[j] - ep) + ts * (e[j] + ep) / (2.0 * ti[j]))
            e_prev[j] = e[j]
        d = d - truth_step[k]
        out[k] = -d
        z = a * z + (1.0 - a) * (gains @ d)
    return out


def fast_autocovariance(e: np.ndarray, lags: int) -> np.ndarray:
    """The autocovariance (lags ``0..lags``) of *e* less its centred 30 min mean, as the band's noise part."""
    from scipy.ndimage import uniform_filter1d

    f = e - uniform_filter1d(e, CENTRE)
    return np.array([float(np.mean(f[: f.size - lag] * f[lag:])) for lag in range(lags + 1)])


def explain(case: Path) -> dict[str, Any]:
    """The figures of one seed's case directory (module docstring)."""
    import pandas as pd
    from scipy.signal import welch

    from trackingbox.diagnose.apply import truth_on
    from trackingbox.identify import held as held_mod
    from trackingbox.identify.bands import NOISE_LAGS, loop_model, loops_noise
    from trackingbox.spec import load_spec
    from trackingbox.tracking.tuning import pair_settings

    spec = load_spec(case / "spec.toml")
    ts = spec.sample_time
    truth = json.loads((case / "truth.json").read_text())
    run = pd.read_csv(case / "track" / "tracking.csv")
    rep = replays(case)
    t = run["time"].to_numpy(float)
    pairs = list(spec.pairs)
    tags, names = [p.variable for p in pairs], [p.parameter for p in pairs]
    found, _ = held_mod.measure(spec, joint=True)
    gains = held_mod.loop_gains(spec, found) if found is not None else None
    if gains is None:
        raise SystemExit(f"explain_evaporator_bands: no invertible gain matrix of the pairs of {case} ({_})")
    loops = []
    for pr in pairs:
        q = spec.parameter(pr.parameter)
        st = pair_settings(pr, q.min, q.max, ts=ts)
        loops.append((float(pr.gain), float(pr.time_constant), st.kp * (q.max - q.min) / st.scaling.span, st.ti))
    tv = np.column_stack([truth_on(truth, n, t) if n in truth.get("trajectories", {})
                          else np.full_like(t, truth["parameters"][n]) for n in names])
    p = np.column_stack([run[f"parameter:{n}"].to_numpy(float) for n in names])
    hold = np.column_stack([(run[f"mode:{v}"].astype(str) != "auto").to_numpy() for v in tags])

    def errors(df: Any) -> np.ndarray:
        e = np.column_stack([(df[f"measured:{v}"] - df[f"tracked:{v}"]).to_numpy(float) for v in tags])
        return np.where(np.isfinite(e), e, 0.0)

    e_a = errors(rep["A"])
    first = int(np.flatnonzero(~hold.any(axis=1) & (t >= spec.tracking.hold_until))[0])
    sl = slice(first, None)
    step = np.vstack([np.diff(tv, axis=0), np.zeros((1, len(names)))])

    def run_with(drive: np.ndarray, ramp: bool) -> np.ndarray:
        out = np.full_like(p, np.nan)
        out[sl] = simulate(gains, loops, ts, drive[sl], step[sl] if ramp else 0.0 * step[sl], hold[sl],
                           p[first] - tv[first])
        return out

    zero = np.zeros_like(e_a)
    drivers = {"all": run_with(e_a, True), "truth's motion": run_with(zero, True)}
    for k, tag in enumerate(tags):
        only = zero.copy()
        only[:, k] = e_a[:, k]
        drivers[f"{tag} at the truth"] = run_with(only, False)
    after = t >= AFTER
    auto = ~hold.any(axis=1) & after
    acf = loops_noise(gains, loops, ts)
    taper = 1.0 - np.arange(NOISE_LAGS + 1) / (NOISE_LAGS + 1.0)
    doc: dict[str, Any] = {"case": str(case), "gains": {"tags": tags, "parameters": names, "matrix": gains.tolist()},
                           "tags": {}, "parameters": {}}
    for k, tag in enumerate(tags):
        gam = fast_autocovariance(e_a[auto, k], NOISE_LAGS)
        level = 2.0 * ts * (gam[0] + 2.0 * float(np.sum((taper * gam)[1:])))
        f, psd = welch(np.where(auto, e_a[:, k], 0.0)[after], fs=1.0 / ts, nperseg=min(16384, int(after.sum())))
        block = {n: float(np.std([np.nanmean(errors(rep[n])[(t >= h * 3600) & (t < (h + 6) * 3600) & auto, k])
                                  for h in range(12, 72, 6)])) for n in rep}
        doc["tags"][tag] = {"fast_sd": math.sqrt(gam[0]),
                            "psd_over_band_level": {f"{1 / fi / 3600:.3g} h": float(pi / level)
                                                    for fi, pi in zip(f[1:8], psd[1:8])},
                            "sd_of_6h_means": block}
    for j, name in enumerate(names):
        if name not in truth.get("trajectories", {}) and name not in truth["parameters"]:
            continue
        miss = tv[:, j] - p[:, j]
        rms = {k: float(np.sqrt(np.mean(v[after, j] ** 2))) for k, v in drivers.items()}
        band = {}
        for k, tag in enumerate(tags):
            gam = fast_autocovariance(e_a[auto, k], NOISE_LAGS)
            var = gam[0] * acf[j, k, 0] + 2.0 * float(np.sum((taper * gam * acf[j, k])[1:])) if acf is not None else math.nan
            band[tag] = math.sqrt(max(var, 0.0))
        # the slope over the loop's lag (two exponential means, as BandTracker took it before 560dba8; it now
        # takes it over bands.RATE_MEMORY, a day) against the truth's: how far that short-memory slope strays
        lag = loop_model(*loops[j][:3], loops[j][3], ts).lag_time
        fast, slow, est = p[first, j], p[first, j], np.zeros_like(t)
        af, as_ = math.exp(-ts / (0.5 * lag)), math.exp(-ts / lag)
        for i in range(first, t.size):
            if np.isfinite(p[i, j]) and not hold[i, j]:
                fast, slow = af * fast + (1 - af) * p[i, j], as_ * slow + (1 - as_) * p[i, j]
            est[i] = (fast - slow) / (0.5 * lag)
        rate = np.gradient(tv[:, j], t)
        moving = after & (rate != 0)
        doc["parameters"][name] = {
            "lag_time": lag,
            **({"truth_rate_x_lag_median": float(np.median(np.abs(rate[moving]) * lag)),
                "own_rate_x_lag_median": float(np.median(np.abs(est[moving]) * lag)),
                "own_rate_wrong_sign": float(np.mean(np.sign(est[moving]) != np.sign(rate[moving])))}
               if moving.any() else {}),
            "miss_rms": float(np.sqrt(np.mean(miss[after] ** 2))),
            "reconstruction_corr": float(np.corrcoef(miss[after], drivers["all"][after, j])[0, 1]),
            "rms_by_driver": rms, "band_noise_sd_by_tag": band}
    return doc


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="explain_evaporator_bands", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="bench_uncertainty's --out (its cases/ are read)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first", type=int, default=0, help="first seed (default 0)")
    args = ap.parse_args(argv)
    ok = True
    for seed in range(args.first, args.first + args.seeds):
        case = args.out / "cases" / f"bands-evaporator-plain-{seed}"
        if not (case / "track" / "result.json").exists():
            print(f"seed {seed}: no run in {case} (scripts/bench_uncertainty --cases bands-evaporator-plain "
                  f"--out {args.out} makes it)", file=sys.stderr)
            ok = False
            continue
        doc = explain(case)
        with open(args.out / "explain-evaporator-bands.jsonl", "a") as f:
            f.write(json.dumps({"seed": seed, **doc}) + "\n")
        print(f"seed {seed} ({case}):")
        for tag, d in doc["tags"].items():
            print(f"  {tag}: fast error sd {d['fast_sd']:.3g}; sd of 6 h mean errors at the truth "
                  + ", ".join(f"{k} {v:.3g}" for k, v in d["sd_of_6h_means"].items())
                  + "; PSD / band level " + ", ".join(f"{k}: {v:.2f}" for k, v in d["psd_over_band_level"].items()))
        for name, d in doc["parameters"].items():
            print(f"  {name}: miss rms {d['miss_rms']:.3g}, linear loops' rms {d['rms_by_driver']['all']:.3g} "
                  f"(corr {d['reconstruction_corr']:.3f}); by driver: "
                  + ", ".join(f"{k} {v:.3g}" for k, v in d["rms_by_driver"].items() if k != "all")
                  + "; band's noise sd by tag: " + ", ".join(f"{k} {v:.3g}" for k, v in d["band_noise_sd_by_tag"].items()))
            if "truth_rate_x_lag_median" in d:
                print(f"    lag part (T_lag {d['lag_time']:.0f} s): truth's rate x T_lag median {d['truth_rate_x_lag_median']:.3g}, "
                      f"the band's (its own rate) {d['own_rate_x_lag_median']:.3g}, of the wrong sign in "
                      f"{100 * d['own_rate_wrong_sign']:.0f} % of the rows")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
