#!/usr/bin/env python3
"""Profile ``diagnose --compile`` on one case folder, in one process (no worker), and print where the time goes.

Usage (the case folder of ``scripts/bench_diagnose``, which holds ``spec.toml``)::

    scripts/profile_diagnose CASE [--workers N] [--top 60]

Writes ``CASE/diagnose`` (the diagnosis's output and work folder) and ``CASE/profile.out``
(``pstats``); prints the verdict, the phases' wall and CPU time and the functions by cumulative
time. With ``--workers 1`` (default) every run and compile is in this process, so the profile
holds all of them.
"""
from __future__ import annotations

import argparse
import cProfile
import logging
import pstats
import sys
import time
from pathlib import Path

from trackingbox.diagnose.stage import DiagnoseSettings, diagnose
from trackingbox.spec import load_spec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case", type=Path)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--top", type=int, default=60)
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    spec = load_spec(args.case / "spec.toml")
    settings = DiagnoseSettings(compile=True, out_dir=args.case / "diagnose", workers=args.workers)
    profile = cProfile.Profile()
    t0 = time.perf_counter()
    profile.enable()
    result = diagnose(spec, settings)
    profile.disable()
    named = result.named
    print(f"wall {time.perf_counter() - t0:.1f} s, verdict {result.verdict}",
          f"{named.effect}@{named.target} {named.values}" if named is not None else "")
    print({k: (round(v.wall), round(v.cpu)) for k, v in result.timings.items()})
    profile.dump_stats(str(args.case / "profile.out"))
    pstats.Stats(profile).sort_stats("cumulative").print_stats(args.top)
    return 0


if __name__ == "__main__":
    sys.exit(main())
