#!/usr/bin/env python3
"""Benchmark: the estimation's refinement with the exact Jacobian (sensitivity runs) beside finite differences.

Runs ``estimate(spec, maxiter=0, jacobian=...)`` (the refinement from the spec's
start values, no global search) once per method on the same case and prints,
per method: the refinement's wall and CPU time (``result.refinement``), its
twin runs (an exact run integrates the sensitivities too), the final training
cost (mean NRMSE) and the parameters. This is a benchmark, not a test.

Examples::

    scripts/bench_jacobian                                    # heat-exchanger bench, seed 0
    scripts/bench_jacobian --bench heat-production --hours 4 --refine-iterations 3
    scripts/bench_jacobian case/spec.toml                     # the README's form: a spec of yours
    scripts/bench_jacobian --spec case/spec.toml --json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / ".cache" / "bench_jacobian"


def main() -> int:
    from trackingbox.estimation import MAX_REFINE_ITERATIONS, estimate
    from trackingbox.spec import load_spec

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bench", default="heat-exchanger", help="bench to generate (default heat-exchanger)")
    parser.add_argument("--hours", type=float, default=None, help="length of the generated bench case")
    parser.add_argument("spec_arg", nargs="?", type=Path, metavar="SPEC",
                        help="use this spec instead of generating a bench case (as --spec)")
    parser.add_argument("--spec", type=Path, help="use this spec instead of generating a bench case")
    parser.add_argument("--seed", type=int, default=0, help="bench seed (default 0)")
    parser.add_argument("--refine-iterations", type=int, default=MAX_REFINE_ITERATIONS)
    parser.add_argument("--methods", default="exact,fd", help="comma-separated jacobian settings (default exact,fd)")
    parser.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    args = parser.parse_args()
    if args.spec_arg is not None and args.spec is not None and args.spec_arg != args.spec:
        parser.error(f"two specs given: {args.spec_arg} and --spec {args.spec}")
    spec_path = args.spec or args.spec_arg
    if spec_path is None:
        from trackingbox.benches import make_bench

        out = CACHE / f"{args.bench}-seed{args.seed}{'' if args.hours is None else f'-{args.hours:g}h'}"
        spec_path = out / "spec.toml"
        if not spec_path.exists():
            print(f"building bench case {args.bench} in {out} ...", file=sys.stderr, flush=True)
            make_bench(args.bench, out, seed=args.seed, **({} if args.hours is None else {"hours": args.hours}))
    spec = load_spec(spec_path)
    rows = {}
    for method in args.methods.split(","):
        print(f"refinement with jacobian={method} ...", file=sys.stderr, flush=True)
        wall, cpu = time.perf_counter(), time.process_time()
        result = estimate(spec, seed=args.seed, maxiter=0, refine_iterations=args.refine_iterations, jacobian=method)
        costs = list(result.training_nrmse.values())
        rows[method] = {**result.refinement, "training_cost": sum(costs) / len(costs),
                        "validation_nrmse": result.validation_nrmse, "parameters": result.parameters,
                        "total_seconds": time.perf_counter() - wall, "total_cpu_seconds": time.process_time() - cpu}
    if args.json:
        print(json.dumps({"spec": str(spec_path), "methods": rows}, indent=2))
        return 0
    print(f"{'method':<8} {'used':<6} {'runs':>5} {'wall s':>8} {'CPU s':>8} {'train cost':>12}  parameters")
    for method, row in rows.items():
        values = ", ".join(f"{k}={v:.6g}" for k, v in row["parameters"].items())
        print(f"{method:<8} {row['jacobian']:<6} {row['runs']:>5} {row['seconds']:>8.1f} {row['cpu_seconds']:>8.1f} "
              f"{row['training_cost']:>12.6g}  {values}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
