"""The embedded compiler on a real library: compile, simulate and check every example of chosen packages.

``scripts/msl`` runs it (see ``--help``). For each example of a package (a class under it that is a
model or block, not partial, with an ``experiment`` annotation), in its own worker process with a
time limit:

1. compile it with the embedded backend from the library's package directory, as a user does
   (``trackingbox compile <MSL>/Modelica --model ... --backend embedded``; the compiler finds
   ``ModelicaServices`` beside ``Modelica`` itself; ``--library`` adds libraries);
2. simulate the FMU over its ``experiment`` (start, stop; the output grid of the reference where
   there is one, else the experiment's interval; relative tolerance :func:`relative_tolerance`: the
   one the reference was made with, else the Modelica Association's rule for making one) with
   fmpy's CVODE (at most :data:`CVODE_MAX_STEPS` internal steps per output interval);
3. compare the reference's comparison signals (``<ref>/<path of the model>/comparisonSignals.txt``
   and ``<Name>.csv``, the Modelica Association's reference results) with the simulation: for each
   signal the largest deviation over the reference's time points, divided by the signal's range in
   the reference (its largest magnitude for a signal constant as far as the reference resolves: within
   ten times its integration tolerance of its magnitude, :data:`RESOLVED_RANGE`). At a reference point the simulation is
   read over a small window either side (1e-4 of the horizon) and the closest value counts, so that an
   event found a hair earlier or later is not a deviation of the whole jump, nor of the ramp it starts.

Outcomes: ``match`` (every signal within 1e-3 of its range), ``close`` (within 1e-2), ``simulated``
(compiled and simulated, no reference on disk), ``refused`` (an
:class:`~trackingbox.errors.UnsupportedConstructError`: grouped by the construct it names),
``error`` (any other compile error, grouped by its first words), ``wrong`` (a signal off by more
than 1e-2 of its range, or missing from the FMU), ``sim-failed`` (the simulation failed), ``crashed``
(the worker died, or an internal error), ``timeout``.

Each result is appended to a JSON-lines file as it finishes (``--resume`` continues, ``--table``
prints the tables of a file), with the compile and simulation seconds and the peak memory of the
worker and of its child processes (the front end, gcc).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import logging
import re
import resource
import signal
import sys
import tempfile
import threading
import time
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import config
from ..isolated import interrupt, run_worker, stop_workers, write_result

log = logging.getLogger(__name__)

DEFAULT_PACKAGES = (
    "Modelica.Thermal.FluidHeatFlow.Examples",
    "Modelica.Thermal.HeatTransfer.Examples",
    "Modelica.Blocks.Examples",
    "Modelica.Electrical.Analog.Examples",
    "Modelica.Mechanics.Rotational.Examples",
    "Modelica.Mechanics.Translational.Examples",
    "Modelica.Fluid.Examples",
)
OUTCOMES = ("match", "close", "simulated", "refused", "error", "wrong", "sim-failed", "crashed", "timeout")
MATCH, CLOSE = 1e-3, 1e-2

CVODE_MAX_STEPS = 1_000_000
"""Internal CVODE steps allowed per output interval (fmpy's default is 500: the MSL's
``Analog.Examples.DifferenceAmplifier`` drives a transistor pair with a 200 MHz damped sine over a
1 s experiment, so 2 ms output steps need far more; ``OpAmps.Multivibrator`` switches fast too)."""
WINDOW = 1e-4
"""Half-width of the time window (fraction of the horizon) read around each reference point: the shift in
time a comparison tolerates."""


# ------------------------------------------------------------------------------------ references
@dataclass(frozen=True)
class Reference:
    """A reference result: the signals to compare and their trajectories."""

    signals: tuple[str, ...]
    time: np.ndarray
    values: dict[str, np.ndarray]
    csv: Path
    tolerance: float | None = None
    """The relative tolerance the reference was integrated with (its ``creation.txt``), if stated."""


def reference_dir(reference_root: Path, model: str) -> Path:
    return reference_root.joinpath(*model.split("."))


def load_reference(reference_root: Path | None, model: str) -> Reference | None:
    """The reference of *model* under *reference_root* (``<root>/Modelica/.../<Name>/``), or None
    when its comparison signals or its CSV are not there."""
    if reference_root is None:
        return None
    folder = reference_dir(reference_root, model)
    names = folder / "comparisonSignals.txt"
    csv = folder / f"{model.rsplit('.', 1)[-1]}.csv"
    if not names.is_file() or not csv.is_file():
        return None
    signals = [s.strip() for s in names.read_text(encoding="utf-8", errors="replace").splitlines() if s.strip()]
    signals = [s for s in signals if s != "time"]
    with open(csv, encoding="utf-8", errors="replace") as fh:
        header = [h.strip().strip('"') for h in fh.readline().strip().split(",")]
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    if data.shape[1] != len(header):
        raise ValueError(f"{csv}: {len(header)} columns in the header, {data.shape[1]} in the data")
    col = {h: k for k, h in enumerate(header)}
    values = {s: data[:, col[s]] for s in signals if s in col}
    missing = [s for s in signals if s not in col]
    if missing:
        raise ValueError(f"{csv} lacks the comparison signals {', '.join(missing)}")
    return Reference(tuple(signals), data[:, col.get("time", 0)], values, csv, _creation_tolerance(folder))


_TOLERANCE_LINE = re.compile(r"^\s*Tolerance\s*=\s*([-+0-9.eE]+)", re.M)


def _creation_tolerance(folder: Path) -> float | None:
    """``Tolerance=`` of the reference's ``creation.txt`` (how the Modelica Association made it)."""
    try:
        found = _TOLERANCE_LINE.search((folder / "creation.txt").read_text(encoding="utf-8", errors="replace"))
        value = float(found.group(1)) if found else None
    except (OSError, ValueError):
        return None
    return value if value is not None and 0 < value < 1 else None


def relative_tolerance(experiment: float | None, reference: float | None) -> float:
    """The relative tolerance an example is simulated with: the reference's own when its
    ``creation.txt`` states it, else the rule the Modelica Association's references were made by
    (the ``experiment`` annotation's ``Tolerance`` times 0.1, 1e-6 without one), and never looser
    than 1e-6.

    >>> relative_tolerance(None, None), relative_tolerance(1e-6, None), relative_tolerance(1e-4, 1e-7)
    (1e-06, 1e-07, 1e-07)
    """
    if reference is not None:
        return min(reference, 1e-6)
    if experiment is not None and experiment > 0:
        return min(experiment / 10, 1e-6)
    return 1e-6


RESOLVED_RANGE = 10.0
"""A reference signal whose range is below this many times its integration tolerance times its
magnitude is constant as far as the reference can tell: a solver at relative tolerance ``tol`` errs
on such a signal by a sizeable part of that range (the Modelica Association's ``TwoTanks`` holds a
tank that only empties at 323.15 K, and its reference moves it by 1.4e-4 K at ``tol`` 1e-6;
``TankWithEmptyingPipe1``'s tank warms by 2.1 mK from its inflow's potential energy, and its
reference leaves the closed form by 1.5e-4 K of it)."""


def deviation(ref_t: np.ndarray, ref_y: np.ndarray, t: np.ndarray, y: np.ndarray, window: float,
              tolerance: float | None = None) -> float:
    """Largest deviation of the trajectory (*t*, *y*) from the reference (*ref_t*, *ref_y*) over the
    reference's points, divided by the reference's range, or by its largest magnitude when the
    signal is constant: exactly, or (with the reference's relative integration *tolerance*) within
    ``RESOLVED_RANGE * tolerance`` of its magnitude, a range the reference does not resolve.

    At each reference point the deviation is the distance from the reference's value to the values the
    trajectory (linear between its points) takes within ±*window* of that time: an event found a hair
    earlier or later, and what follows it (a ramp it starts, a fast transient), is not a deviation as
    long as the shift is within the window, as the Modelica Association's tube comparison tolerates a
    shift in time; a wrong value, jump or slope beyond the shift still is.

    >>> t, r = np.linspace(0, 1, 11), np.linspace(0.1, 0.9, 9)
    >>> round(deviation(r, r, t, t + 0.001, 0.0), 6), round(deviation(r, r, t, t + 0.001, 1e-4), 6)
    (0.00125, 0.001125)
    """
    scale = float(np.max(ref_y) - np.min(ref_y)) if ref_y.size else 0.0
    magnitude = float(np.max(np.abs(ref_y))) if ref_y.size else 0.0
    if tolerance:
        unresolved = RESOLVED_RANGE * tolerance * magnitude
    else:
        unresolved = 1e-12 * max(1.0, magnitude)
    if not scale > unresolved:
        scale = magnitude
    if not scale > 0:
        scale = 1.0
    if not ref_t.size:
        return 0.0
    order = np.argsort(t, kind="stable")
    t, y = t[order], y[order]
    lo_t, hi_t = np.clip(ref_t - window, t[0], t[-1]), np.clip(ref_t + window, t[0], t[-1])
    ends = np.stack([np.interp(lo_t, t, y), np.interp(hi_t, t, y)])
    lo, hi = ends.min(axis=0), ends.max(axis=0)
    # between its points the trajectory is linear: its extremes in the window are at the window's
    # ends or at its points inside
    first, stop = np.searchsorted(t, lo_t, side="right"), np.searchsorted(t, hi_t, side="left")
    inside = stop > first
    if inside.any():
        padded = np.r_[y, np.nan]
        bounds = np.stack([first[inside], stop[inside]], axis=1).ravel()
        lo[inside] = np.minimum(lo[inside], np.minimum.reduceat(padded, bounds)[::2])
        hi[inside] = np.maximum(hi[inside], np.maximum.reduceat(padded, bounds)[::2])
    best = np.maximum(0.0, np.maximum(lo - ref_y, ref_y - hi))
    return float(np.max(best) / scale)


def compare(ref: Reference, time_: np.ndarray, values: dict[str, np.ndarray]) -> tuple[float, str, list[str]]:
    """(worst relative deviation, the signal, signals missing from *values*)."""
    horizon = float(ref.time[-1] - ref.time[0]) if ref.time.size else 1.0
    worst, where, missing = 0.0, "", []
    for s in ref.signals:
        if s not in values:
            missing.append(s)
            continue
        d = deviation(ref.time, ref.values[s], time_, values[s], WINDOW * max(horizon, 1e-12), ref.tolerance)
        if not np.isfinite(d):
            d = np.inf
        if d >= worst:
            worst, where = d, s
    return worst, where, missing


# ------------------------------------------------------------------------------------ the worker
def _peak_mb() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return round(own, 1), round(kids, 1)


def _cpu() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def run_example(request: dict) -> dict:
    """Compile, simulate and compare one example in this process (see the module docstring)."""
    from . import InternalCompileError, compile_model
    from ..errors import CompileError, TrackingError, UnsupportedConstructError

    model = request["model"]
    out: dict = {"model": model}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="tbx-msl-") as tmp:
        fmu = Path(tmp) / (model.rsplit(".", 1)[-1] + ".fmu")
        try:
            result = compile_model(request["source"], model, backend="embedded", output=fmu,
                                   libraries=request.get("libraries", []))
        except InternalCompileError as exc:
            return {**out, "outcome": "crashed", "message": str(exc), "compile_s": time.perf_counter() - t0}
        except UnsupportedConstructError as exc:
            return {**out, "outcome": "refused", "message": str(exc), "compile_s": time.perf_counter() - t0}
        except CompileError as exc:
            text = str(exc)
            outcome = ("crashed" if "front end crashed" in text else
                       "timeout" if "front end did not finish" in text else "error")
            return {**out, "outcome": outcome, "message": text, "compile_s": time.perf_counter() - t0}
        except TrackingError as exc:
            return {**out, "outcome": "error", "message": f"{type(exc).__name__}: {exc}",
                    "compile_s": time.perf_counter() - t0}
        out["compile_s"] = round(time.perf_counter() - t0, 2)
        out["states"] = result.states
        out["peak_compile_mb"] = _peak_mb()
        ref_root = Path(request["reference"]) if request.get("reference") else None
        try:
            ref = load_reference(ref_root, model)
        except (OSError, ValueError) as exc:
            return {**out, "outcome": "crashed", "message": f"reference unreadable: {exc}"}
        t1 = time.perf_counter()
        errors: list[str] = []
        try:
            sim = simulate(fmu, ref, errors)
        except Exception as exc:  # noqa: BLE001 - fmpy raises plain exceptions for FMU failures
            said = f" (the FMU: {errors[-1][:1000]})" if errors else ""
            return {**out, "outcome": "sim-failed", "message": f"{type(exc).__name__}: {str(exc)[:1500]}{said}",
                    "sim_s": round(time.perf_counter() - t1, 2)}
        out["sim_s"] = round(time.perf_counter() - t1, 2)
        time_, values, problems = sim
        if problems:
            return {**out, "outcome": "sim-failed", "message": problems}
        if ref is None:
            return {**out, "outcome": "simulated", "message": "no reference on disk"}
        worst, where, missing = compare(ref, time_, values)
        out["deviation"] = worst if np.isfinite(worst) else "inf"
        out["signal"] = where
        if missing:
            return {**out, "outcome": "wrong",
                    "message": f"signals of the reference missing from the FMU: {', '.join(missing)}"}
        outcome = "match" if worst <= MATCH else "close" if worst <= CLOSE else "wrong"
        return {**out, "outcome": outcome,
                "message": f"largest deviation {worst:.3g} of the signal's range, on {where}"}


@contextlib.contextmanager
def _cvode_steps(steps: int):
    """fmpy 0.3.32's ``simulate_fmu`` builds its CVODE solver with 500 steps per output interval and
    no way to pass more: while in this block it builds one with *steps* (the harness's worker runs one
    simulation at a time)."""
    from fmpy import sundials

    original = sundials.CVodeSolver

    class Solver(original):  # type: ignore[misc, valid-type]
        def __init__(self, *args, **kwargs):
            kwargs["maxNumSteps"] = steps
            super().__init__(*args, **kwargs)

    sundials.CVodeSolver = Solver
    try:
        yield
    finally:
        sundials.CVodeSolver = original


def fmu_errors(sink: list[str]):
    """An fmpy logger keeping the FMU's own error-level messages (status 3 and above) in *sink*: a
    failed call then says why (\"initialisation failed ...: their solve gives x = nan\"), not only
    which FMI function failed."""
    def logger(*args) -> None:
        status, message = args[-3], args[-1]
        if int(status) >= 3:
            sink.append(message.decode(errors="replace") if isinstance(message, bytes) else str(message))
    return logger


def simulate(fmu: Path, ref: Reference | None, errors: list[str] | None = None
             ) -> tuple[np.ndarray, dict[str, np.ndarray], str]:
    """Simulate *fmu* over its default experiment; (time, {signal: values}, problem or "").
    *errors*: receives the FMU's error-level log messages (:func:`fmu_errors`)."""
    import fmpy

    md = fmpy.read_model_description(str(fmu))
    exp = md.defaultExperiment
    start = float(exp.startTime) if exp is not None and exp.startTime is not None else 0.0
    stop = float(exp.stopTime) if exp is not None and exp.stopTime is not None else 1.0
    tol = relative_tolerance(float(exp.tolerance) if exp is not None and exp.tolerance is not None else None,
                             ref.tolerance if ref is not None else None)
    names = {v.name for v in md.modelVariables}
    if ref is not None and ref.time.size > 1:
        # the reference's output grid (its typical step: points at events are a hair apart)
        steps = np.diff(ref.time)
        steps = steps[steps > 0]
        interval = float(np.median(steps)) if steps.size else (stop - start) / 500
    elif exp is not None and exp.stepSize is not None:
        interval = float(exp.stepSize)
    else:
        interval = (stop - start) / 500
    interval = max(interval, (stop - start) / 200_000)
    wanted = [s for s in (ref.signals if ref is not None else ()) if s in names]
    with _cvode_steps(CVODE_MAX_STEPS):
        result = fmpy.simulate_fmu(str(fmu), start_time=start, stop_time=stop, relative_tolerance=tol,
                                   output_interval=interval, output=wanted or None, fmi_type="ModelExchange",
                                   logger=fmu_errors(errors) if errors is not None else None)
    time_ = np.asarray(result["time"], dtype=float)
    values = {s: np.asarray(result[s], dtype=float) for s in (wanted or result.dtype.names[1:])}
    bad = [s for s, v in values.items() if not np.all(np.isfinite(v))]
    problem = ""
    if bad:
        problem = f"non-finite values of {', '.join(bad[:5])}"
    elif time_.size == 0 or time_[-1] < stop - 1e-9 * max(1.0, abs(stop)):
        problem = f"the simulation stopped at t = {time_[-1] if time_.size else start:g} before {stop:g}"
    return time_, {s: values[s] for s in wanted}, problem


def _worker_main(argv: list[str]) -> int:
    """``python -m trackingbox.compiler.msl_harness --one REQUEST.json``: one example, JSON on stdout."""
    request = json.loads(Path(argv[0]).read_text())
    logging.basicConfig(level=logging.WARNING)
    t0 = time.perf_counter()
    try:
        result = run_example(request)
    except BaseException as exc:  # noqa: BLE001 - the point is to classify everything
        import traceback

        result = {"model": request["model"], "outcome": "crashed",
                  "message": f"{type(exc).__name__}: {exc}\n" + "".join(traceback.format_exc(limit=-3))}
    result["wall_s"] = round(time.perf_counter() - t0, 2)
    result["cpu_s"] = round(_cpu(), 2)
    result["peak_mb"], result["peak_children_mb"] = _peak_mb()
    write_result(result)
    return 0


# ------------------------------------------------------------------------------------ grouping
def construct_of(record: dict) -> str:
    """The construct (for ``refused``) or the kind of error (for ``error``) a refusal names,
    without the model's own names, paths and numbers, so that like refusals group together."""
    msg = record.get("message", "")
    model = record.get("model", "")
    first = msg.strip().splitlines()[0] if msg.strip() else ""
    text = first
    m = re.search(r"unsupported Modelica construct(?: in [\w.]+)?: (.*)", first)
    if m:
        text = m.group(1)
        text = re.split(r" at /| \(rumoca| \(the front end|\. The embedded backend|\. The front end| in function ",
                        text)[0]
    else:
        text = re.sub(r"^cannot compile '[^']*' from \S+: ", "", text)
        text = text.replace(model, "<model>")
        text = re.split(r" at /|[:;] variables not determined|; equations|\(", text)[0]
    text = re.sub(r"'[^']*'|`[^`]*`|\"[^\"]*\"", "…", text)
    text = re.sub(r"/\S+\.mo(?::\d+)*", "<file>", text)
    text = re.sub(r"\b\d+(?:\.\d+)?\b", "N", text)
    text = re.sub(r"\b(?:Modelica|ModelicaServices)(?:\.\w+)+", "…", text)
    return text.strip(" .:;,")[:120] or "(no message)"


# ------------------------------------------------------------------------------------ the runner
def run_isolated(request: dict, timeout: float, cpu_limit: float | None = None) -> dict:
    """Run one example in a fresh worker process with a time limit (wall s, and CPU s where given);
    never raises for the model's sake."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="tbx-msl-req-") as tmp:
        req = Path(tmp) / "request.json"
        req.write_text(json.dumps(request))
        cmd = [sys.executable, "-m", "trackingbox.compiler.msl_harness", "--one", str(req)]
        result = run_worker(cmd, timeout, cpu_limit)
    if result is None:
        limit = f"{cpu_limit:g} CPU s or " if cpu_limit is not None else ""
        result = {"outcome": "timeout", "message": f"no result after {limit}{timeout:g} s"}
    result["model"] = request["model"]
    result["package"] = request["package"]
    result["seconds"] = round(time.perf_counter() - t0, 2)
    result["message"] = str(result.get("message", "")).strip()[:4000]
    if result["outcome"] in ("refused", "error"):
        result["construct"] = construct_of(result)
    return result


def load_results(path: Path) -> dict[str, dict]:
    """Results already in a JSON-lines file, by model (later lines win; a cut last line is skipped)."""
    done: dict[str, dict] = {}
    if path.is_file():
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(rec, dict) and "model" in rec:
                done[rec["model"]] = rec
    return done


def table(results: list[dict], packages: list[str] | None = None) -> str:
    """One table per package: counts per outcome, refusals and errors grouped by construct, and the
    compile time and peak memory of the compiled examples (median and largest)."""
    by_pkg: dict[str, list[dict]] = defaultdict(list)
    for r in results:
        by_pkg[r.get("package", "?")].append(r)
    order = [p for p in (packages or []) if p in by_pkg] + sorted(p for p in by_pkg if p not in (packages or []))
    head = f"{'package':42s} {'n':>4s} " + " ".join(f"{o:>10s}" for o in OUTCOMES)
    lines = [head, "-" * len(head)]
    total: Counter = Counter()
    for pkg in order:
        rows = by_pkg[pkg]
        count = Counter(r["outcome"] for r in rows)
        total.update(count)
        lines.append(f"{pkg:42s} {len(rows):4d} " + " ".join(f"{count.get(o, 0):10d}" for o in OUTCOMES))
    lines.append(f"{'TOTAL':42s} {sum(total.values()):4d} " + " ".join(f"{total.get(o, 0):10d}" for o in OUTCOMES))
    for pkg in order:
        rows = by_pkg[pkg]
        lines.append("")
        lines.append(f"{pkg}:")
        groups: dict[tuple[str, str], list[str]] = defaultdict(list)
        for r in rows:
            if r["outcome"] in ("refused", "error"):
                groups[(r["outcome"], r.get("construct") or construct_of(r))].append(r["model"].rsplit(".", 1)[-1])
        for (outcome, construct), models in sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0])):
            lines.append(f"  {len(models):3d} {outcome:7s} {construct}: {', '.join(sorted(models))}")
        for r in sorted(rows, key=lambda r: r["model"]):
            if r["outcome"] in ("wrong", "sim-failed", "crashed", "timeout", "close"):
                lines.append(f"      {r['outcome']:10s} {r['model'].rsplit('.', 1)[-1]}: {r.get('message', '')[:160]}")
        compiled = [r for r in rows if r.get("compile_s") is not None and r["outcome"] in
                    ("match", "close", "simulated", "wrong", "sim-failed")]
        if compiled:
            cs = sorted(float(r["compile_s"]) for r in compiled)
            mem = sorted(max(r.get("peak_mb") or 0, r.get("peak_children_mb") or 0) for r in compiled)
            lines.append(f"  compiled {len(compiled)}: compile s median {cs[len(cs) // 2]:.1f} max {cs[-1]:.1f}; "
                         f"peak MB (largest process) median {mem[len(mem) // 2]:.0f} max {mem[-1]:.0f}")
    return "\n".join(lines)


def default_msl() -> Path:
    """``../shared/msl/Modelica`` beside the repository, or ``$TRACKINGBOX_MSL``."""
    env = config.get("msl")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3].parent / "shared" / "msl" / "Modelica"


def default_reference() -> Path:
    """``../shared/msl-reference`` beside the repository, or ``$TRACKINGBOX_MSL_REFERENCE``."""
    env = config.get("msl_reference")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[3].parent / "shared" / "msl-reference"


def siblings(package_dir: Path) -> list[Path]:
    """The other top-level packages beside a library's package directory (``ModelicaServices``,
    ``Complex.mo`` beside ``Modelica``)."""
    out = []
    for p in sorted(package_dir.parent.iterdir()):
        if p == package_dir:
            continue
        if (p.is_dir() and (p / "package.mo").is_file()) or (p.is_file() and p.suffix == ".mo"):
            out.append(p)
    return out


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--one"]:
        return _worker_main(argv[1:])
    p = argparse.ArgumentParser(
        prog="scripts/msl",
        description="Compile every example of Modelica Standard Library packages with the embedded backend, "
                    "simulate it over its experiment, compare it with the reference results, and print a "
                    "table per package.",
        epilog="examples:\n  scripts/msl --package Modelica.Thermal.HeatTransfer.Examples -j 1\n"
               "  scripts/msl --match TwoMasses\n  scripts/msl --resume\n  scripts/msl --table msl-out/results.jsonl",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--msl", type=Path, default=None,
                   help="the library's package directory (default: ../shared/msl/Modelica)")
    p.add_argument("--library", action="append", type=Path, default=[], metavar="DIR",
                   help="further library given to the compiler (repeatable; the packages beside --msl, e.g. "
                        "ModelicaServices, are found without it)")
    p.add_argument("--reference", type=Path, default=None,
                   help="reference results root (default: ../shared/msl-reference)")
    p.add_argument("--package", action="append", default=[],
                   help="package whose examples to run (repeatable; default: the issue's seven)")
    p.add_argument("--match", action="append", default=[], help="only examples whose name contains this "
                   "(repeatable)")
    p.add_argument("--out", type=Path, default=Path("msl-out/results.jsonl"),
                   help="JSON-lines results file, written as examples finish (default: %(default)s)")
    p.add_argument("-j", "--jobs", type=int, default=1, help="parallel worker processes (default: 1)")
    p.add_argument("--timeout", type=float, default=600.0, help="wall seconds per example (default: 600)")
    p.add_argument("--cpu-timeout", type=float, default=None, metavar="S",
                   help="CPU seconds per example, compile and simulation, its processes together (the limit a "
                        "loaded machine does not move; --timeout stays the wall limit)")
    p.add_argument("--resume", action="store_true", help="skip examples already in --out")
    p.add_argument("--table", type=Path, default=None, metavar="RESULTS",
                   help="only print the tables of an existing results file and exit")
    p.add_argument("--list", action="store_true", help="only list the examples found and exit")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    packages = args.package or list(DEFAULT_PACKAGES)
    if args.table is not None:
        if not args.table.is_file():
            print(f"error: results file {args.table} not found", file=sys.stderr)
            return 2
        results = list(load_results(args.table).values())
        if args.match:
            results = [r for r in results if any(m in r["model"] for m in args.match)]
        if args.package:
            results = [r for r in results if r.get("package") in args.package]
        print(table(results, packages))
        return 0
    msl = (args.msl or default_msl()).resolve()
    if not (msl / "package.mo").is_file():
        print(f"error: library package {msl} not found (no package.mo); give --msl", file=sys.stderr)
        return 2
    libraries = [p.resolve() for p in args.library]
    reference = (args.reference or default_reference()).resolve()
    if not reference.is_dir():
        log.info("no reference results at %s: examples are only simulated", reference)
        reference = None
    from .library import LibraryIndex

    index = LibraryIndex.build([msl, *libraries, *siblings(msl)])
    todo_all: list[dict] = []
    for pkg in packages:
        if pkg not in index.classes:
            print(f"error: package {pkg} not found in {msl}", file=sys.stderr)
            return 2
        for model in index.examples(pkg):
            if args.match and not any(m in model for m in args.match):
                continue
            todo_all.append({"model": model, "package": pkg, "source": str(msl),
                             "libraries": [str(x) for x in libraries],
                             "reference": str(reference) if reference else None})
    if args.list:
        for r in todo_all:
            print(r["model"])
        return 0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    done = load_results(args.out) if args.resume else {}
    if not args.resume:
        args.out.write_text("", encoding="utf-8")
    todo = [r for r in todo_all if r["model"] not in done]
    log.info("%d examples (%d already done), %d jobs, %g s%s per example -> %s",
             len(todo_all), len(todo_all) - len(todo), args.jobs, args.timeout,
             f" ({args.cpu_timeout:g} CPU s)" if args.cpu_timeout is not None else "", args.out)
    lock = threading.Lock()
    t0 = time.perf_counter()
    signal.signal(signal.SIGTERM, interrupt)
    pool = ThreadPoolExecutor(max(1, args.jobs))
    try:
        with open(args.out, "a", encoding="utf-8") as fh:
            futures = {pool.submit(run_isolated, r, args.timeout, args.cpu_timeout): r for r in todo}
            for k, fut in enumerate(as_completed(futures), 1):
                res = fut.result()
                with lock:
                    fh.write(json.dumps(res, default=str) + "\n")
                    fh.flush()
                done[res["model"]] = res
                log.info("[%d/%d] %-66s %-10s %6.1f s %s", k, len(todo), res["model"], res["outcome"],
                         res["seconds"], res.get("construct", ""))
    except KeyboardInterrupt:
        pool.shutdown(wait=False, cancel_futures=True)
        stop_workers()
        log.info("interrupted: the results so far are in %s (continue with --resume)", args.out)
        return 130
    pool.shutdown()
    names = {r["model"] for r in todo_all}
    results = [r for n, r in done.items() if n in names]
    print(table(results, packages))
    print(f"{len(results)} examples in {time.perf_counter() - t0:.0f} s; per-example results in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
