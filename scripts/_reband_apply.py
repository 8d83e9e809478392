"""The bands of ``diagnose --apply``'s runs recomputed with this checkout's code, with and without part 7's carry.

A diagnostic (not a test) for a case folder of ``scripts/bench_apply`` (``WORK/BENCH/CASE-xNOISE-sSEED``). For each
run in its ``apply/apply.json`` (the unpatched re-track and each round's) it recomputes the band columns of the run's
tracking CSV with :class:`trackingbox.identify.bands.BandTracker` (``scripts/_bench_uncertainty.rebanded``, the
fixed part, gain matrix and closed-loop gains as ``track`` measures them: :func:`trackingbox.identify.held.band_parts`)
twice: as the code is, and with the model-error part's readings not carried to the other pairs (``carry`` None:
each pair its own readings, as before :func:`trackingbox.identify.misfit.follows`). Per tracked parameter the truth
knows it prints the share of the rows after settling whose band holds the plant's truth and the median half-width:
as tracked (the CSV), and both recomputations. A run tracked with the code of the second reproduces its CSV.

    scripts/reband_apply WORK/evaporator/default-x1-s0
    scripts/reband_apply OUT/cases/bands-evaporator-plain-0     (a demo's folder: its one run)
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv: list[str] | None = None) -> int:
    import pandas as pd

    from _bench_uncertainty import band_coverage, rebanded

    from trackingbox.diagnose.apply import truth_on
    from trackingbox.identify import bands as bands_mod
    from trackingbox.identify.held import band_parts
    from trackingbox.spec import load_spec

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case", type=Path, help="a case folder of scripts/bench_apply (with truth.json and apply/), or a "
                                            "demo's --out folder (spec.toml, truth.json, track/tracking.csv)")
    ap.add_argument("--settle", type=float, default=12 * 3600.0,
                    help="s from which a demo folder's rows count (default 12 h, the evaporator's)")
    args = ap.parse_args(argv)
    truth = json.loads((args.case / "truth.json").read_text())
    if (args.case / "apply" / "apply.json").is_file():
        doc = json.loads((args.case / "apply" / "apply.json").read_text())
        runs = [("unpatched", doc.get("before"))] + [(f"round {r['round']}", r.get("retrack"))
                                                     for r in doc.get("rounds", [])]
    else:  # a demo's folder (scripts/bench_uncertainty's evaporator cases): its one run, scored after --settle
        names = [p.parameter for p in load_spec(args.case / "spec.toml").pairs]
        runs = [("tracked", {"spec": str(args.case / "spec.toml"), "csv": str(args.case / "track" / "tracking.csv"),
                             "errors": {n: {"settle": args.settle} for n in names}})]
    original = bands_mod.BandTracker.__init__

    def not_carried(self, *a, **k):  # noqa: ANN001, ANN002, ANN003 - the tracker's own arguments
        original(self, *a, **k)
        self.carry = None

    for label, run in runs:
        if not run:
            continue
        spec_path, csv = Path(run["spec"]), Path(run["csv"])
        spec = load_spec(spec_path)
        fixed, note, gains, misfit = band_parts(spec)
        carried = rebanded(csv, spec_path, fixed=fixed, gains=gains, misfit=misfit, spec=spec)
        bands_mod.BandTracker.__init__ = not_carried
        try:
            alone = rebanded(csv, spec_path, fixed=fixed, gains=gains, misfit=misfit, spec=spec)
        finally:
            bands_mod.BandTracker.__init__ = original
        t = pd.read_csv(csv, usecols=["time"])["time"].to_numpy(float)
        print(f"{label}: pairs {', '.join(f'{p.parameter} on {p.variable}' for p in spec.pairs)}", flush=True)
        for p in spec.pairs:
            e = run.get("errors", {}).get(p.parameter)
            tr = truth_on(truth, p.parameter, t)
            if tr is None or e is None:
                continue
            for what, source in (("as tracked", csv), ("not carried", alone), ("carried", carried)):
                c = band_coverage(source, p.parameter, tr, float(e["settle"]))
                print(f"    {p.parameter} ({what}): holds the truth in {100 * c['covered']:.1f} % of {c['rows']} rows "
                      f"after settling (below it {100 * c['below']:.1f} %), median half-width "
                      f"{c['median_half_width']:.4g}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
