"""``trackingbox pair``: choose tracking parameters for tracking variables (RGA and/or Sobol)."""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import AnalysisError, SpecError

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  trackingbox pair case1/spec.toml
  trackingbox pair case2/spec.toml --freeze holdControllers=1 --report case2/pair
  trackingbox pair case2/spec.toml --method both --samples 64 --workers 2 --json --no-write
  trackingbox pair case2/spec.toml --scheduler tcp://10.0.0.5:8786     # run on a Dask cluster

Procedure: the twin's inputs are held at an operating point (mean of the first
hour of the training window, or --at TIME); the twin runs with its controllers
active until it settles; the --freeze values are set (e.g. holdControllers=1)
and it settles again; then each [[parameters]] entry is stepped by +/- --step of
its bound range and the new steady state of every [outputs] tag is recorded.
Tank levels listed in [[states]] are held by proportional state compensation
from the freeze on (they are not tracking variables).
Settled = over --window seconds no output moved more than --tolerance x its
measured range; responses are measured against an unstepped reference run, so
a slow residual drift is not taken for a gain. Gains g_ij = dy_i/dp_j, scaled
by measured ranges and parameter bound ranges, give the relative gain array
(after leaving out parameters that cannot be told apart, see --rank-tol); each
tag gets the unused parameter with a positive relative gain closest to 1.

Data checks (off with --no-data-checks): before the assignment the twin runs
untracked over the training window with the measured inputs (parameters at
their starts, [[states]] compensation on, the first [tracking] hold_until
seconds left out) and is compared with the measurements. A tag whose untracked
RMS error is below --noise-ratio x its sensor noise (robust std of first
differences / sqrt 2) has nothing to track and is left out. A pair is allowed
only if the parameter's remaining range toward the measurement moves the tag
by at least --min-reach x its mean offset. The chosen set is then simulated as
first-order loops with the parameters clipped to their bounds; while a pair
would leave more than --max-ratio of its tag's untracked RMS error, the worst
one is forbidden and the assignment redone. Reasons go to the left-out list.
With --second-point (default auto) the step tests are repeated at the hour of
the training window whose mean inputs differ most from the first point: a pair
whose gain changes sign between the points is not chosen, and each pair is
written with the larger of its two gains (and that point's time constant), so
the loop, tuned for the highest gain seen, stays stable where the gain grows.
The chosen pairs (gain, 63 % time
constant) replace the spec's [[pairs]] unless --no-write; an existing pair keeps
its tuning settings (lambda, kp, ti, controller; a new pair gets lambda = 1, the
tuning factor; the relative gain is reported, not written). Exit code 1 when no
pair could be chosen.
"""


def register(subparsers: Any) -> None:
    """Add the ``pair`` subcommand."""
    p = subparsers.add_parser(
        "pair",
        help="pair tracking variables with tracking parameters (step tests + RGA, or Sobol)",
        description="Steady-state step tests on the twin with its controllers frozen, relative gain "
                    "array and assignment; optional Sobol sensitivity as a cross-check.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, help="spec.toml")
    p.add_argument("--method", choices=("rga", "sobol", "both"), default="rga",
                   help="rga: pairs from the relative gain array (default); sobol: pairs from Sobol total "
                        "indices; both: RGA pairs plus Sobol indices and their agreement")
    p.add_argument("--step", type=float, default=0.05,
                   help="parameter step as a fraction of its bound range (default 0.05)")
    p.add_argument("--one-sided", action="store_true", help="only step up (no -step linearity check)")
    p.add_argument("--freeze", action="append", default=[], metavar="NAME=VALUE",
                   help="input or tunable parameter that freezes the twin's controllers, set after the first "
                        "settle (repeatable), e.g. --freeze holdControllers=1")
    p.add_argument("--at", type=float, metavar="TIME",
                   help="operating point: measurements interpolated at TIME (s from the first sample) "
                        "instead of the mean of the first hour of the training window")
    p.add_argument("--interval", type=float, metavar="SECONDS",
                   help="communication step of the step tests (default: the spec's sample_time)")
    p.add_argument("--window", type=float, metavar="SECONDS",
                   help="settle window (default: 60 intervals)")
    p.add_argument("--tolerance", type=float, default=1e-4,
                   help="settled when no output moves more than this fraction of its range over the "
                        "window (default 1e-4)")
    p.add_argument("--baseline-tolerance", type=float, default=1e-3,
                   help="the same for the settle phases before the steps (default 1e-3; the rest of "
                        "their drift is removed by measuring against an unstepped reference run)")
    p.add_argument("--max-time", type=float, default=86400.0, metavar="SECONDS",
                   help="longest a phase may take to settle (default 86400 s)")
    p.add_argument("--rank-tol", type=float, default=None, metavar="RTOL",
                   help="leave out parameters whose scaled gain column adds less than RTOL x the largest "
                        "singular value (cannot be told apart from the others; default 1e-2)")
    p.add_argument("--second-point", default="auto", metavar="auto|none|TIME",
                   help="repeat the step tests at a second operating point: auto (default) = the hour of the "
                        "training window whose mean inputs differ most (relatively) from the first point; "
                        "TIME = measurements interpolated there; none = skip. A pair whose gain changes sign "
                        "between the points is not chosen; a pair takes the larger of its two gains (tuning "
                        "for the highest gain seen keeps the loop stable where the gain grows)")
    p.add_argument("--no-data-checks", dest="data_checks", action="store_false",
                   help="pair from the gains alone (no untracked run over the training window)")
    p.add_argument("--noise-ratio", type=float, default=5.0, metavar="K",
                   help="leave out tags whose untracked RMS error is below K x their sensor noise "
                        "(default 5)")
    p.add_argument("--min-reach", type=float, default=0.5, metavar="F",
                   help="allow a pair only if the parameter's remaining range moves the tag by at least "
                        "F x its mean untracked offset (default 0.5)")
    p.add_argument("--max-ratio", type=float, default=0.25, metavar="R",
                   help="reject pairs predicted to leave more than R of the tag's untracked RMS error "
                        "(default 0.25)")
    p.add_argument("--samples", type=int, default=32,
                   help="Sobol base sample size N, a power of two; N*(D+2) runs (default 32)")
    p.add_argument("--seed", type=int, default=0, help="Sobol sampling seed (default 0)")
    p.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: all cores)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask distributed scheduler to run on")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    p.add_argument("--report", type=Path, metavar="DIR", help="write RGA/gain heatmaps and a Markdown summary")
    p.add_argument("--no-write", dest="write", action="store_false", help="do not write [[pairs]] to SPEC")
    p.set_defaults(func=run)


def parse_freeze(items: list[str]) -> dict[str, float]:
    """``["holdControllers=1"]`` -> ``{"holdControllers": 1.0}``; :class:`AnalysisError` on bad syntax."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not name or not math.isfinite(number):
            raise AnalysisError(f"--freeze {item!r}: expected NAME=VALUE with a number, e.g. holdControllers=1")
        out[name] = number
    return out


def _stderr(text: str) -> None:
    sys.stderr.write(text + "\n")
    sys.stderr.flush()


class _Progress:
    """``stage: done/total`` on stderr, rewritten in place on a terminal."""

    def __init__(self, stage: str) -> None:
        self.stage = stage
        self.tty = sys.stderr.isatty()
        self.last = -1

    def __call__(self, done: int, total: int) -> None:
        if self.tty:
            sys.stderr.write(f"\r\033[K{self.stage}: {done}/{total}" + ("\n" if done == total else ""))
        else:
            step = max(1, total // 10)
            if done != total and done // step == self.last:
                return
            self.last = done // step
            sys.stderr.write(f"{self.stage}: {done}/{total}\n")
        sys.stderr.flush()


def _measured(spec: Any) -> tuple[Any, float, float]:
    from ..data import read_table

    frame = read_table(spec.measurements, required=list(spec.inputs) + list(spec.outputs), allow_nan=True)
    t = frame["time"].to_numpy(dtype=float)
    start, stop = spec.windows.get("training", (float(t[0]), float(t[-1]) + 1.0))
    return frame, float(start), float(stop)


def analyse(spec: Any, args: argparse.Namespace) -> dict[str, Any]:
    """Run the analysis the arguments ask for; returns the pieces (no output written)."""
    from ..analysis.executor import make_executor
    from dataclasses import replace

    from ..analysis.pairing import Pair, choose_pairs
    from ..analysis.rga import parameter_ranges, variable_ranges
    from ..analysis.sobol import agreement, sobol_indices
    from ..analysis.steptest import StepSettings, make_problem, operating_point, step_tests
    from ..data import window as take_window

    freeze = parse_freeze(args.freeze)
    frame, start, stop = _measured(spec)
    op = operating_point(frame, spec.inputs, start=start, duration=3600.0, at=args.at)
    train = take_window(frame, start, stop)
    state_tags = {st.tag for st in spec.states}
    tags = [t for t in spec.outputs if t not in state_tags]
    if state_tags:
        _stderr("state-compensated tags are not tracking variables: " + ", ".join(sorted(state_tags)))
    spans = variable_ranges(train[tags].to_numpy(dtype=float)) if len(train) else np.full(len(tags), np.nan)
    ranges = {tag: float(r) for tag, r in zip(tags, spans) if math.isfinite(r) and r > 0}
    params = [(p.name, p.start, p.min, p.max) for p in spec.parameters]
    problem = make_problem(spec.twin, outputs={t: spec.outputs[t] for t in tags}, parameters=params,
                           fixed=spec.fixed, operating=op, ranges=ranges, freeze=freeze,
                           compensation=[(st.variable, st.correction, st.gain) for st in spec.states])
    interval = float(args.interval or spec.sample_time)
    settings = StepSettings(step=args.step, two_sided=not args.one_sided, freeze=tuple(freeze.items()),
                            interval=interval, window=float(args.window or 60 * interval),
                            tolerance=args.tolerance, baseline_tolerance=args.baseline_tolerance,
                            max_time=args.max_time)
    pranges = parameter_ranges([(p.min, p.max) for p in spec.parameters])
    sob = None
    with make_executor(args.scheduler, args.workers) as ex:
        _stderr(f"step tests: {len(params)} parameters x {2 if settings.two_sided else 1} directions, "
                f"{len(tags)} variables")
        st = step_tests(problem, settings, ex, progress=_Progress("step runs"))
        _stderr(f"step tests done: {st.runs} runs in {st.seconds:.1f} s (controllers frozen at "
                f"t = {st.freeze_time:g} s, steps at t = {st.step_time:g} s)")
        second = _second_point(args, frame, spec, op, start, stop)
        st2 = None
        if second is not None:
            at2, op2 = second
            _stderr(f"second operating point (t = {at2:g} s): "
                    + ", ".join(f"{k} = {v:.4g}" for k, v in op2.items()))
            st2 = step_tests(replace(problem, fixed=tuple((k, v) for k, v in problem.fixed if k not in op2)
                                     + tuple(op2.items())), settings, ex, progress=_Progress("step runs (2nd point)"))
            _stderr(f"step tests at the second point done: {st2.runs} runs in {st2.seconds:.1f} s")
        if args.method in ("sobol", "both"):
            _stderr(f"Sobol: {args.samples * (len(params) + 2)} runs")
            sob = sobol_indices(problem, settings, n=args.samples, seed=args.seed, executor=ex,
                                progress=_Progress("Sobol runs"))
            _stderr(f"Sobol done in {sob.seconds:.1f} s")
    residuals = checks = None
    if getattr(args, "data_checks", True):
        from ..analysis.offsets import simulate_untracked
        from ..analysis.pairing import DataChecks

        checks = DataChecks(noise_ratio=args.noise_ratio, min_reach=args.min_reach, max_ratio=args.max_ratio)
        _stderr(f"data checks: untracked twin over the training window [{start:g}, {stop:g}) s")
        residuals = simulate_untracked(spec, st.variables, start=start, stop=stop)
    pairing = choose_pairs(st.gains, st.variables, st.parameters, time_constants=st.time_constants,
                           variable_ranges=st.ranges, parameter_ranges=pranges,
                           residuals=residuals, bounds=[(p.start, p.min, p.max) for p in spec.parameters],
                           checks=checks, other_gains=None if st2 is None else st2.gains,
                           other_time_constants=None if st2 is None else st2.time_constants,
                           **({"rtol": args.rank_tol} if args.rank_tol else {}))
    agr = agreement(pairing, sob) if sob is not None else None
    if args.method == "sobol" and sob is not None:
        choice = sob.choice("total")
        idx = {n: k for k, n in enumerate(st.parameters)}
        pairs = []
        for i, v in enumerate(st.variables):
            if v in choice:
                j = idx[choice[v]]
                pairs.append(Pair(v, choice[v], float(pairing.rga[i, j]), float(st.gains[i, j]),
                                  float(st.time_constants[i, j])))
        chosen = {p.parameter for p in pairs} | {p.variable for p in pairs}
        left = tuple((n, "not chosen by the Sobol total indices") for n in (*st.variables, *st.parameters)
                     if n not in chosen)
        pairing = replace(pairing, pairs=tuple(pairs), left_out=left)
    warnings = list(pairing.warnings)
    for v, p, a in st.nonlinear():
        warnings.append(f"{v}/{p}: +/- step gains differ by {100 * a:.0f} % (nonlinear response)")
    return {"steptest": st, "pairing": pairing, "sobol": sob, "agreement": agr, "settings": settings,
            "warnings": warnings, "operating_point": op, "steptest_second": st2,
            "second_point": None if second is None else {"time": second[0], "inputs": second[1]}}


def _second_point(args: argparse.Namespace, frame: Any, spec: Any, op: dict[str, float], start: float,
                  stop: float) -> tuple[float, dict[str, float]] | None:
    """The second operating point the arguments ask for, or None."""
    from ..analysis.steptest import farthest_operating_point, operating_point

    choice = str(getattr(args, "second_point", "auto")).strip().lower()
    if choice == "none":
        return None
    if choice == "auto":
        return farthest_operating_point(frame, spec.inputs, op, start=start, stop=stop)
    try:
        at = float(choice)
    except ValueError:
        raise AnalysisError(f"--second-point {args.second_point!r}: expected auto, none or a time in s") from None
    return at, operating_point(frame, spec.inputs, at=at)


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _matrix(rows: tuple[str, ...], cols: tuple[str, ...], values: np.ndarray) -> dict[str, Any]:
    return {"variables": list(rows), "parameters": list(cols),
            "values": [[_finite(float(x)) for x in row] for row in np.asarray(values, dtype=float)]}


def to_json(res: dict[str, Any]) -> dict[str, Any]:
    """The ``--json`` document."""
    st, pairing, sob, agr = res["steptest"], res["pairing"], res["sobol"], res["agreement"]
    doc: dict[str, Any] = {
        "pairs": [{"variable": p.variable, "parameter": p.parameter, "lambda": _finite(p.lambda_),
                   "gain": _finite(p.gain), "time_constant": _finite(p.time_constant),
                   "predicted_ratio": _finite(p.predicted_ratio), "at_bound": _finite(p.at_bound)}
                  for p in pairing.pairs],
        "gain_matrix": _matrix(st.variables, st.parameters, st.gains),
        "rga": _matrix(st.variables, st.parameters, pairing.rga),
        "condition_number": _finite(pairing.condition_number),
        "left_out": [{"name": n, "reason": r} for n, r in pairing.left_out],
        "warnings": res["warnings"],
        "asymmetry": _matrix(st.variables, st.parameters, st.asymmetry),
        "time_constants": _matrix(st.variables, st.parameters, st.time_constants),
        "operating_point": res["operating_point"],
        "step_time": st.step_time,
        "runs": st.runs + (sob.runs + 1 if sob is not None else 0),
        "sobol": None,
        "agreement": None,
        "pairs_condition_number": _finite(pairing.pairs_condition_number),
        "data_checks": None if pairing.checks is None else {
            "noise_ratio": pairing.checks.noise_ratio, "min_reach": pairing.checks.min_reach,
            "max_ratio": pairing.checks.max_ratio},
        "offsets": [{"variable": o.variable, "noise": _finite(o.noise), "mean": _finite(o.mean),
                     "rms": _finite(o.rms), "noise_ratio": _finite(o.noise_ratio), "samples": o.samples}
                    for o in pairing.offsets],
        "rejected_pairs": [{"variable": v, "parameter": p, "reason": r} for v, p, r in pairing.rejected],
        "second_operating_point": res.get("second_point"),
        "gain_matrix_second": None if res.get("steptest_second") is None else
        _matrix(st.variables, st.parameters, res["steptest_second"].gains),
    }
    if res.get("steptest_second") is not None:
        doc["runs"] += res["steptest_second"].runs
    if sob is not None:
        doc["sobol"] = {"first": _matrix(sob.variables, sob.parameters, sob.first),
                        "total": _matrix(sob.variables, sob.parameters, sob.total),
                        "samples": sob.samples, "runs": sob.runs}
    if agr is not None:
        doc["agreement"] = {"index": agr.index, "agree": agr.agree, "compared": agr.compared,
                            "rows": [{"variable": v, "rga": a, "sobol": b, "same": s} for v, a, b, s in agr.rows]}
    return doc


def spec_pairs(spec: Any, pairing: Any, interval: float) -> list[Any]:
    """PairSpec entries for the chosen pairs; an existing identical pair keeps its tuning settings."""
    from dataclasses import replace

    from ..spec import PairSpec

    old = {(p.variable, p.parameter): p for p in spec.pairs}
    out = []
    for p in pairing.pairs:
        tau = p.time_constant if math.isfinite(p.time_constant) and p.time_constant > 0 else interval
        if not (math.isfinite(p.time_constant) and p.time_constant > 0):
            log.warning("pair %s/%s has no measurable time constant; writing %g s (the step interval)",
                        p.variable, p.parameter, interval)
        prev = old.get((p.variable, p.parameter))
        if prev is not None:
            out.append(replace(prev, gain=float(p.gain), time_constant=float(tau)))
        else:
            out.append(PairSpec(variable=p.variable, parameter=p.parameter, gain=float(p.gain),
                                time_constant=float(tau), lambda_=1.0))
    return out


def run(args: argparse.Namespace) -> int:
    """Run ``trackingbox pair``; exit code 0 on success."""
    from ..spec import check_against_fmu, load_spec, write_pairs

    spec = load_spec(args.spec)
    check_against_fmu(spec)
    if not spec.parameters:
        raise SpecError(f"{spec.path} has no [[parameters]]: nothing to pair")
    res = analyse(spec, args)
    pairing = res["pairing"]
    if args.report:
        paths = write_report(spec, res, args.report)
        _stderr(f"report: {', '.join(str(p) for p in paths)}")
    if args.write:
        if pairing.pairs:
            write_pairs(spec.path, spec_pairs(spec, pairing, res["settings"].interval))
            _stderr(f"wrote {len(pairing.pairs)} pairs to {spec.path}")
        else:
            _stderr(f"no pairs found; {spec.path} left unchanged")
    if args.json:
        print(json.dumps(to_json(res), indent=2))
    else:
        _print_summary(res)
    return 0 if pairing.pairs else 1


def _print_summary(res: dict[str, Any]) -> None:
    pairing, st = res["pairing"], res["steptest"]
    if pairing.pairs:
        wv = max(8, *(len(p.variable) for p in pairing.pairs))
        wp = max(9, *(len(p.parameter) for p in pairing.pairs))
        print(f"{'variable':<{wv}}  {'parameter':<{wp}}  {'lambda':>8}  {'gain':>12}  {'tau (s)':>9}")
        for p in pairing.pairs:
            print(f"{p.variable:<{wv}}  {p.parameter:<{wp}}  {p.lambda_:>8.3f}  {p.gain:>12.4g}  "
                  f"{p.time_constant:>9.4g}")
    else:
        print("no pairs found")
    print(f"\ncondition number (scaled gains): {pairing.condition_number:.4g}; {st.runs} step-test runs")
    for name, reason in pairing.left_out:
        print(f"left out {name}: {reason}")
    for w in res["warnings"]:
        print(f"warning: {w}")
    agr = res["agreement"]
    if agr is not None:
        print(f"Sobol ({agr.index} index) agrees with the RGA for {agr.agree} of {agr.compared} variables")


def _heatmap(path: Path, title: str, rows: tuple[str, ...], cols: tuple[str, ...], values: np.ndarray,
             pairs: set[tuple[str, str]], *, cmap: str, center: float | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import TwoSlopeNorm
    from matplotlib.patches import Rectangle

    from ..io import atomic_path

    V = np.asarray(values, dtype=float)
    fig, ax = plt.subplots(figsize=(max(5.0, 2.5 + 0.8 * len(cols)), max(3.0, 1.6 + 0.5 * len(rows))))
    finite = V[np.isfinite(V)]
    norm = None
    if center is not None and finite.size and finite.min() < center < finite.max():
        norm = TwoSlopeNorm(vcenter=center, vmin=float(finite.min()), vmax=float(finite.max()))
    im = ax.imshow(np.ma.masked_invalid(V), cmap=cmap, norm=norm, aspect="auto")
    for i in range(len(rows)):
        for j in range(len(cols)):
            text = "" if not np.isfinite(V[i, j]) else f"{V[i, j]:.2g}"
            ax.text(j, i, text, ha="center", va="center", fontsize=8)
            if (rows[i], cols[j]) in pairs:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, lw=2.5, ec="black"))
    ax.set_xticks(range(len(cols)), cols, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(rows)), rows, fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.colorbar(im, ax=ax, shrink=0.8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def write_report(spec: Any, res: dict[str, Any], out: Path) -> list[Path]:
    """RGA and scaled-gain heatmaps (PNG, chosen pairs boxed) and ``pairing.md`` in *out*."""
    from ..io import write_text_atomic

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    st, pairing, sob, agr = res["steptest"], res["pairing"], res["sobol"], res["agreement"]
    chosen = {(p.variable, p.parameter) for p in pairing.pairs}
    written = []
    target = out / "rga.png"
    _heatmap(target, "relative gain array (boxed: chosen pairs)", st.variables, st.parameters, pairing.rga,
             chosen, cmap="RdBu_r", center=1.0)
    written.append(target)
    target = out / "gains_scaled.png"
    _heatmap(target, "scaled steady-state gains (range-normalised)", st.variables, st.parameters,
             pairing.scaled_gains, chosen, cmap="PuOr", center=0.0)
    written.append(target)
    if sob is not None:
        target = out / "sobol_total.png"
        _heatmap(target, "Sobol total-effect indices", sob.variables, sob.parameters, sob.total, chosen,
                 cmap="viridis")
        written.append(target)

    s = res["settings"]
    lines = [
        f"# Pairing: {Path(spec.path).name}",
        "",
        f"Twin `{Path(spec.twin).name}`; inputs held at "
        + ", ".join(f"`{k}` = {v:.4g}" for k, v in res["operating_point"].items())
        + f". Controllers frozen at t = {st.freeze_time:g} s"
        + (f" ({', '.join(f'`{n}` = {v:g}' for n, v in s.freeze)})" if s.freeze else " (no freeze input given)")
        + f"; parameters stepped by {'+/-' if s.two_sided else '+'}{100 * s.step:g} % of their bound range "
        f"at t = {st.step_time:g} s. Settle rule: change below {s.tolerance:g} x range over {s.window:g} s. "
        f"{st.runs} step-test runs in {st.seconds:.1f} s."
        + ("" if res.get("second_point") is None else
           f" Repeated at a second operating point (the hour from t = {res['second_point']['time']:g} s: "
           + ", ".join(f"`{k}` = {v:.4g}" for k, v in res["second_point"]["inputs"].items())
           + "); each pair's gain is the larger of the two."),
        "",
        "## Chosen pairs",
        "",
        "| variable | parameter | lambda | gain | time constant (s) |",
        "|---|---|---:|---:|---:|",
    ]
    for p in pairing.pairs:
        lines.append(f"| {p.variable} | {p.parameter} | {p.lambda_:.3f} | {p.gain:.4g} | {p.time_constant:.4g} |")
    lines += ["", f"Condition number of the scaled gain matrix: {pairing.condition_number:.4g}; of the "
              f"chosen pairs: {pairing.pairs_condition_number:.4g}.", ""]
    if pairing.checks is not None:
        c = pairing.checks
        lines += ["## Data checks", "",
                  "The twin ran untracked over the training window with the measured inputs. Noise = robust "
                  "standard deviation of the measurement's first differences / sqrt(2). Thresholds: "
                  f"untracked RMS error at least {c.noise_ratio:g} x noise; the parameter's remaining range "
                  f"closes at least {c.min_reach:g} x the mean offset; predicted tracked/untracked RMS ratio "
                  f"(all pairs together, first-order loops, parameters clipped) at most {c.max_ratio:g}.", "",
                  "| variable | noise | mean offset | RMS error | RMS / noise |", "|---|---:|---:|---:|---:|"]
        lines += [f"| {o.variable} | {o.noise:.3g} | {o.mean:.3g} | {o.rms:.3g} | {o.noise_ratio:.3g} |"
                  for o in pairing.offsets]
        lines += ["", "| pair | predicted ratio | time at a bound |", "|---|---:|---:|"]
        lines += [f"| {p.variable} / {p.parameter} | {p.predicted_ratio:.2f} | {100 * p.at_bound:.0f} % |"
                  for p in pairing.pairs]
        if pairing.rejected:
            lines += ["", "Pairs rejected by the prediction:", ""]
            lines += [f"- {v} / {p}: {r}" for v, p, r in pairing.rejected]
        lines += [""]
    if pairing.left_out:
        lines += ["## Left out", ""] + [f"- `{n}`: {r}" for n, r in pairing.left_out] + [""]
    if res["warnings"]:
        lines += ["## Warnings", ""] + [f"- {w}" for w in res["warnings"]] + [""]
    lines += ["## Relative gain array", "", "![RGA](rga.png)", "",
              "| | " + " | ".join(st.parameters) + " |", "|---|" + "---:|" * len(st.parameters)]
    for i, v in enumerate(st.variables):
        lines.append(f"| {v} | " + " | ".join("" if not np.isfinite(x) else f"{x:.3g}" for x in pairing.rga[i]) + " |")
    lines += ["", "## Steady-state gains (engineering units)", "", "![scaled gains](gains_scaled.png)", "",
              "| | " + " | ".join(st.parameters) + " |", "|---|" + "---:|" * len(st.parameters)]
    for i, v in enumerate(st.variables):
        lines.append(f"| {v} | " + " | ".join(f"{x:.3g}" for x in st.gains[i]) + " |")
    if sob is not None:
        lines += ["", f"## Sobol total-effect indices (N = {sob.samples}, {sob.runs} runs)", "",
                  "![Sobol](sobol_total.png)", "",
                  "| | " + " | ".join(sob.parameters) + " |", "|---|" + "---:|" * len(sob.parameters)]
        for i, v in enumerate(sob.variables):
            lines.append(f"| {v} | " + " | ".join(f"{x:.2f}" for x in sob.total[i]) + " |")
    if agr is not None:
        lines += ["", f"Sobol and RGA choose the same parameter for {agr.agree} of {agr.compared} variables:", ""]
        lines += [f"- {v}: RGA `{a}`, Sobol `{b}`" + ("" if same else " (differs)" if a and b else " (not compared)")
                  for v, a, b, same in agr.rows if a or b]
    target = out / "pairing.md"
    write_text_atomic(target, "\n".join(lines) + "\n")
    written.append(target)
    target = out / "pairing.json"
    write_text_atomic(target, json.dumps(to_json(res), indent=2) + "\n")
    written.append(target)
    return written
