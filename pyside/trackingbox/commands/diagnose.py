"""``trackingbox diagnose``: where twin and plant disagree, which missing effect explains it, the patch."""
from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

from ..io import check_output
from ..report.diagnose import write_diagnose_report
from ..spec import check_against_fmu, load_spec
from ..stages import diagnose as stage
from ..stages.contract import settings_from_args
from . import SUMMARIES
from ._args import add_executor_arguments, add_library_option, number, with_libraries
from ._progress import Progress

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  trackingbox diagnose case1/spec.toml
  trackingbox diagnose case1/spec.toml --json
  trackingbox diagnose case1/spec.toml --compile --report case1/diagnose -o case1/patched
  trackingbox diagnose case1/spec.toml --effects sensor-bias,sensor-drift
  trackingbox diagnose case1/spec.toml --apply --truth case1/truth.json -o case1/apply

The null model is the twin with the spec's [[parameters]] fitted on the training
window. Every tag's residual is described against its noise level; every effect
of the library (built-ins plus the spec's [diagnose] effects folders) is screened
on every target it applies to; without --compile only the cheap screening runs
(sensor effects as transforms of the simulated output, fouling as a coefficient
ramp); with --compile the compile-only entries (heat-loss, leak) are compiled
once each and screened linearised in their parameters, the best candidates are
fitted through their patched, compiled twin (jointly with the spec's parameters)
and the named patch's FMU is built. The null model is refined from the spec's
starts (--maxiter N adds a global search); with more than 3 candidates the
estimations refine on a 60 s grid. Verdict (exit code 0 for each): effect | none | unexplained. -o DIR writes
<Twin>Diagnosed.mo, its diff and (when an FMU was built) the patched spec.

--apply closes the loop (implies --compile, needs -o): the named effect's patched
twin is re-estimated, re-paired and re-tracked over the same data, and so is the
unpatched twin; the patched spec is diagnosed again, up to --apply-rounds times,
until nothing more is named. With --truth (a bench's truth.json: the plant's
parameters and trajectories) the tracked parameters' largest and median error after
settling are reported before and after, and plotted (DIR/apply.png, DIR/apply.md).
The pipeline is the demo's for the bench --truth names (its "bench"; on the
evaporators the estimates become the starts), else estimate's defaults with the
spec's starts kept. A parameter of [diagnose] varying (tracked in time) that pair's
data checks refuse is paired all the same with the tag its relative gain chose, and
the refusal is printed: the comparison needs it tracked before and after. Every round is
written to DIR/apply.json as it finishes. Nothing named in the first round: an
error (exit 2), and nothing is left in DIR.
"""


def register(subparsers: Any) -> None:
    """Add the ``diagnose`` subcommand."""
    p = subparsers.add_parser(
        "diagnose",
        help=SUMMARIES["diagnose"],
        description="Discrepancy diagnosis: residuals, effect screening, fit, judgement on held-out data.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--report", type=Path, metavar="DIR", help="write the diagnosis report (Markdown, plots) to DIR")
    p.add_argument("-o", "--output", type=Path, metavar="DIR",
                   help="write <Twin>Diagnosed.mo, its diff and the patched spec to DIR")
    add_library_option(p, "diagnose --compile compiles the patched twin")
    p.add_argument("--compile", action="store_true",
                   help="fit the best candidates through their patched, compiled twin and build the patch's FMU")
    p.add_argument("--effects", default="", metavar="ID,...", help="only these effect ids (comma-separated)")
    p.add_argument("--fit-best", type=number(ge=1, integer=True), default=2, metavar="N",
                   help="candidates fitted properly with --compile in a round (default 2; the first round adds the best-scored one on training where it is not among them)")
    p.add_argument("--fit-rounds", type=number(ge=1, integer=True), default=3, metavar="N",
                   help="rounds of fits at most: another round while no fitted candidate passes (default 3)")
    p.add_argument("--seed", type=number(ge=0, integer=True), default=0,
                   help="seed of the null model's estimation (default 0)")
    add_executor_arguments(p, what="the estimations and the screening jobs",
                           default="2 when the spec has more than 3 candidates, else 1")
    p.add_argument("--maxiter", type=number(ge=0, integer=True), default=None,
                   help="generations of the null model's global search (default 0: least-squares "
                        "refinement from the spec's starts only; give one when the starts are far off)")
    p.add_argument("--warmup", type=number(ge=0), default=None, metavar="SECONDS",
                   help="unscored warm-up before each window (default: estimate's)")
    p.add_argument("--apply", action="store_true",
                   help="apply the named effect: re-estimate, re-pair and re-track the patched twin, diagnose "
                        "again (implies --compile; needs -o)")
    p.add_argument("--apply-rounds", type=number(ge=1, integer=True), default=3, metavar="N",
                   help="--apply: rounds of diagnose and apply at most (default 3)")
    p.add_argument("--resume", action="store_true",
                   help="--apply: reuse what DIR/apply.json holds of an interrupted run (its namings, finished "
                        "re-tracks)")
    p.add_argument("--truth", type=Path, metavar="FILE",
                   help="--apply: the plant's truth (a bench's truth.json) to measure the tracked parameters "
                        "against")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the diagnosis; exit code 0 for every verdict."""
    spec = with_libraries(load_spec(args.spec), args.library)
    inputs = [spec.path, spec.twin, spec.measurements]
    for option, value in (("--report", args.report), ("-o", args.output)):
        if value is not None:
            check_output(value, option, kind="dir", inputs=inputs)
    check_against_fmu(spec)
    settings = settings_from_args(stage.DiagnoseSettings, args, out_dir=args.output,
                                  effects=tuple(e.strip() for e in args.effects.split(",") if e.strip()))
    if args.apply or args.truth is not None:
        return _apply(args, spec, settings)
    result = stage.run(spec, settings, progress=Progress(every=15.0))
    if args.report:
        write_diagnose_report(spec, result, args.report)
    if args.json:
        print(json.dumps(result.to_json(), indent=2))
        return 0
    _print(result)
    if args.report:
        print(f"report in {args.report}")
    return 0


def _apply(args: argparse.Namespace, spec: Any, settings: Any) -> int:
    """``--apply``: diagnose, apply, re-track, per round (:func:`trackingbox.diagnose.apply.apply`)."""
    from ..diagnose.apply import ApplyError, apply, bench_recipe

    if not args.apply:
        raise ApplyError("--truth is an option of --apply")
    if args.report is not None:
        raise ApplyError("--report is not written with --apply: its report is DIR/apply.md (-o DIR)")
    if args.output is None:
        raise ApplyError("--apply needs -o DIR (the patched twins, the re-tracked runs and apply.json go there)")
    truth = None
    if args.truth is not None:
        try:
            truth = json.loads(Path(args.truth).read_text())
        except (OSError, ValueError) as exc:
            raise ApplyError(f"--truth {args.truth}: cannot read it as JSON: {exc}") from exc
        if not isinstance(truth, dict) or not ({"parameters", "trajectories"} & set(truth)):
            raise ApplyError(f"--truth {args.truth}: no 'parameters' or 'trajectories' table (a bench's truth.json)")
    bench = truth.get("bench") if truth else None
    recipe = bench_recipe(bench, spec.parameter_names)
    result = apply(spec, settings, truth=truth, recipe=recipe, out=args.output, rounds=args.apply_rounds,
                   resume=args.resume, note=lambda text: print(text, flush=True) if not args.json else log.info(text))
    if args.json:
        print(json.dumps(result.to_json(), indent=2, default=str))
        return 0
    before = result.before
    for k in (before.kept if before else ()):
        print(f"unpatched: {k['parameter']} paired with {k['variable']} although pair refused it ({k['refused']}): "
              "the parameter the spec tracks in time is compared before and after the patch")
    for r in result.rounds:
        named = r.get("named")
        print(f"round {r['round']}: " + (f"named {named['effect']} on {named['target']}" if named
                                          else f"nothing named (verdict {r['verdict']})"))
        for k in (r.get("retrack") or {}).get("kept", []):
            print(f"  {k['parameter']} paired with {k['variable']} although pair refused it ({k['refused']})")
        for name, e in (r.get("retrack") or {}).get("errors", {}).items():
            b = before.errors.get(name) if before else None
            print(f"  {name}: largest error after settling {b.max_error:.4g} -> {e['max_error']:.4g}, median "
                  f"{b.median_error:.4g} -> {e['median_error']:.4g}" if b else f"  {name}: {e}")
    if result.stopped:
        print(f"stopped: {result.stopped}")
    for name, ratio in result.ratios().items():
        print(f"{name}: largest error after / before = {ratio:.3f}")
    if result.plot:
        print(f"plot: {result.plot}")
    print(f"results: {args.output / 'apply.json'}, report: {args.output / 'apply.md'}")
    return 0


def _print(result: Any) -> None:
    print(f"verdict: {result.verdict}")
    c = result.named
    if c is not None:
        values = ", ".join(f"{k} = {v:.4g}" for k, v in c.values.items())
        print(f"named: {c.effect} on {c.target} ({values}); delta BIC {c.delta_bic:.1f}")
        for tag in c.tags:
            print(f"  {tag}: validation NRMSE {c.nrmse_before[tag]:.4g} -> {c.nrmse_after[tag]:.4g}")
    for tag, periods in result.judgement.unexplained.items():
        where = ", ".join(f"{a / 3600:.1f}-{b / 3600:.1f} h" for a, b in periods) or "throughout"
        print(f"unexplained residual on {tag}: {where}")
    print(f"\n{'effect':<14} {'target':<12} {'stage':<8} {'delta BIC':>10} {'valid gain':>10}")
    for cand in result.candidates[:10]:
        print(f"{cand.effect:<14} {cand.target:<12} {cand.stage:<8} {cand.delta_bic:>10.4g} "
              f"{cand.validation_gain:>10.3g}")
    if result.patch_file:
        print(f"\npatch: {result.patch_file}")
    if result.patch_spec:
        print(f"patched spec: {result.patch_spec}")
    print(f"{result.seconds:.1f} s")
