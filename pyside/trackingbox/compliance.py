"""Run the Modelica compliance suite through the embedded compile path.

Every test model of the suite (a class annotated
``__ModelicaAssociation(TestCase(shouldPass = true|false, ...))``) is compiled
from the suite's package with the embedded backend, in its own worker process
with a time limit; the valid ones are then simulated over their ``experiment``
so that their ``assert``\\ s are evaluated. Each model gets one outcome:

``pass``
    valid, compiled and simulated to the end (its asserts held).
``refused-construct``
    valid, refused naming an unsupported construct (UnsupportedConstructError).
``refused-other``
    valid, refused with any other compile error.
``crashed``
    the worker died (signal, abort), raised something that is not a
    :class:`~trackingbox.errors.TrackingError` (a traceback for the user), or the
    compiler reported an internal error (an unexpected exception it caught), or
    the front end crashed (rumoca died in its worker process).
``hang``
    the worker did not finish within the time limit.
``wrong-values``
    valid, compiled, and an assert failed during the simulation.
``sim-failed``
    valid, compiled, and the simulation failed for another reason.
``rejected`` / ``accepted``
    an invalid model (``shouldPass = false``) was refused (compile or
    simulation error) / compiled and simulated without complaint.

Every refusal at compile time (``refused-*`` and ``rejected`` before simulation) is
also checked for its position (:func:`location_verdict`): the first ``file.mo:line``
it names must lie inside the model's own class definition in its own file, and where
the refusal names a construct (``when``, ``algorithm``, ``der(``, ...) that line must
contain it. The table's ``loc:bad`` column counts the refusals that fail this, and
lists them below the table.

Results are appended to a JSON-lines file as each model finishes, so an
interrupted run keeps what it computed (``--resume`` continues it; ``--table FILE``
prints the table of a results file without running anything). Run it as
``scripts/compliance`` (see ``--help``).
"""
from __future__ import annotations

import argparse
import json
import logging
import re
import signal
import sys
import tempfile
import threading
import time
import traceback
from collections import Counter
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

from . import config
from .compiler import InternalCompileError, compile_model
from .compiler.source import (
    class_lines,
    experiment_settings,
    read_text,
    resolve_source,
    strip_comments,
)
from .errors import (
    CompileError,
    SimulationError,
    TrackingError,
    UnsupportedConstructError,
)
from .isolated import interrupt, run_worker, stop_workers, write_result
from .simulation.models import open_model

log = logging.getLogger(__name__)

Outcome = Literal["pass", "refused-construct", "refused-other", "crashed", "hang", "wrong-values",
                  "sim-failed", "rejected", "accepted"]
VALID_OUTCOMES: tuple[str, ...] = ("pass", "refused-construct", "refused-other", "crashed", "hang",
                                   "wrong-values", "sim-failed")
INVALID_OUTCOMES: tuple[str, ...] = ("rejected", "accepted", "crashed", "hang")

_TESTCASE = re.compile(r"TestCase\s*\(\s*shouldPass\s*=\s*(true|false)")
_WITHIN = re.compile(r"^\s*within\s+([\w.]+)\s*;", re.M)
_DECL = re.compile(r"\b(?:(?:partial|encapsulated|final|replaceable)\s+)*"
                   r"(?:model|block|class|package|connector|record|function|type)\s+([A-Za-z_]\w*)")
_END = re.compile(r"\bend\s+([A-Za-z_]\w*)\s*;")
_LOCATION = re.compile(r"(/[^\s:,()]+\.mo):(\d+)")


@dataclass(frozen=True)
class TestModel:
    """One test model of the suite."""

    name: str
    file: Path
    should_pass: bool

    @property
    def section(self) -> str:
        """The suite's top-level section (``Arrays``, ``Operators``, ...)."""
        parts = self.name.split(".")
        return parts[1] if len(parts) > 2 else parts[0]


@dataclass(frozen=True)
class ModelResult:
    """The outcome of one test model (one line of the results file)."""

    model: str
    section: str
    should_pass: bool
    outcome: str
    message: str
    seconds: float
    file: str
    locations: tuple[tuple[str, int], ...] = ()
    stage: str = "compile"  # where the outcome was decided: "compile" or "simulate"

    def to_json(self) -> dict:
        d = asdict(self)
        d["locations"] = [list(x) for x in self.locations]
        return d


def _strip(text: str) -> str:
    return strip_comments(text)


def discover(suite: Path) -> list[TestModel]:
    """The test models of the suite package directory *suite* (sorted by name).

    A test model is the class whose annotation holds ``TestCase(shouldPass=...)``;
    its name is the file's ``within`` prefix plus the enclosing classes.
    """
    suite = Path(suite)
    models: list[TestModel] = []
    for file in sorted(suite.rglob("*.mo")):
        raw = file.read_text(encoding="utf-8-sig", errors="replace")
        hits = list(_TESTCASE.finditer(raw))
        if not hits:
            continue
        code = _strip(raw)
        within = _WITHIN.search(code)
        prefix = within.group(1) if within else ""
        # short class definitions (type E = enumeration(...);) have no end, and "function f(...)"
        # in an expression is a partial application: neither encloses anything
        events = sorted([(m.start(), "decl", m.group(1)) for m in _DECL.finditer(code)
                         if not re.match(r"\s*[=(]", code[m.end():])]
                        + [(m.start(), "end", m.group(1)) for m in _END.finditer(code)])
        for hit in hits:
            stack: list[str] = []
            for pos, kind, name in events:
                if pos > hit.start():
                    break
                if kind == "decl":
                    stack.append(name)
                elif name in stack:
                    del stack[len(stack) - 1 - stack[::-1].index(name):]
            if not stack:
                continue
            name = ".".join(p for p in (prefix, *stack) if p)
            models.append(TestModel(name, file, hit.group(1) == "true"))
    return sorted(models, key=lambda m: m.name)


def locations_in(message: str) -> tuple[tuple[str, int], ...]:
    """The ``file.mo:line`` positions a message names."""
    return tuple((f, int(n)) for f, n in _LOCATION.findall(message))


_CONSTRUCT_TEXT: tuple[tuple[str, str], ...] = (
    # (what the refusal's own words name, what the text of the line it points at must then hold)
    (r"\bwhen-clause|\bwhen[- ](?:equation|statement)|`when`", r"\bwhen\b"),
    (r"\balgorithm\b", r"\balgorithm\b"),
    (r"\bpre\(", r"\bpre\s*\("),
    (r"\bedge\(", r"\bedge\s*\("),
    (r"\bsample\(", r"\bsample\s*\("),
    (r"\breinit\(", r"\breinit\s*\("),
    (r"\binitial\(\)", r"\binitial\s*\("),
    (r"\bterminal\(\)", r"\bterminal\s*\("),
    (r"\bder\(", r"\bder\s*\("),
    (r"\bexternal function", r"\bexternal\b"),
    (r"\bif-equation", r"\bif\b"),
    (r"\barray dimension or for-range\b", r"\bfor\b|\["),
    (r"\bfor-(?:loop|equation|range)|\bloop index\b|\bexplicit range\b", r"\bfor\b"),
)
LOCATION_VERDICTS: tuple[str, ...] = ("ok", "missing", "outside", "construct")


def location_verdict(record: dict) -> str | None:
    """Whether a compile-time refusal names the model's own class and the right line.

    ``None`` for outcomes that are not refusals at compile time (passes, simulation
    failures, crashes); else ``"ok"``; ``"missing"`` (no ``file.mo:line`` in the
    message); ``"outside"`` (the first position named is not inside the model's own
    class definition in its own file); ``"construct"`` (the message names a construct
    such as ``when`` or ``der(`` and the line pointed at does not contain it).
    """
    if record["outcome"] not in ("refused-construct", "refused-other", "rejected"):
        return None
    message = record.get("message", "")
    stage = record.get("stage") or ("simulate" if re.search(r"\.fmu\b", message) else "compile")
    if stage != "compile":
        return None
    locs = locations_in(message)
    if not locs:
        return "missing"
    file, line = locs[0]
    lines = class_lines(Path(record["file"]), record["model"])
    if file != record["file"] or lines is None or not lines[0] <= line <= lines[1]:
        return "outside"
    words = message[: message.find(file)]  # the refusal's own words, before the position
    words = words.split("(rumoca:", 1)[0]
    expected = [holds for named, holds in _CONSTRUCT_TEXT if re.search(named, words)]
    if expected:  # the line holds (one of) the construct(s) the refusal names
        text = read_text(Path(file)).splitlines()
        here = text[line - 1] if line <= len(text) else ""
        if not any(re.search(holds, here) for holds in expected):
            return "construct"
    return "ok"


def _assert_failure(message: str) -> bool:
    return "assert" in message.lower()


def run_one(model: TestModel, suite: Path, workdir: Path) -> tuple[str, str, str]:
    """Compile (and simulate, for a valid model) *model* in this process: (outcome, message, stage)."""
    fmu = workdir / (model.name.rsplit(".", 1)[-1] + ".fmu")
    try:
        compile_model(suite, model.name, backend="embedded", output=fmu)
    except InternalCompileError as exc:  # a clean message for the user, but a bug of ours: count it
        return "crashed", str(exc), "compile"
    except UnsupportedConstructError as exc:
        return ("refused-construct" if model.should_pass else "rejected"), str(exc), "compile"
    except CompileError as exc:
        text = str(exc)
        if "front end crashed" in text:
            return "crashed", text, "compile"
        if "front end did not finish" in text:
            return "hang", text, "compile"
        return ("refused-other" if model.should_pass else "rejected"), text, "compile"
    except TrackingError as exc:
        return ("refused-other" if model.should_pass else "rejected"), f"{type(exc).__name__}: {exc}", "compile"
    settings = experiment_settings(resolve_source(suite), model.name)
    start = settings.get("StartTime", 0.0)
    stop = settings.get("StopTime", 1.0)
    if stop <= start:
        stop = start + 1e-6
    interval = settings.get("Interval", (stop - start) / 100)
    try:
        with open_model(fmu, tolerance=settings.get("Tolerance", 1e-6)) as fm:
            fm.simulate(start_time=start, stop_time=stop, output_interval=interval)
    except SimulationError as exc:
        text = str(exc)
        if not model.should_pass:
            return "rejected", text, "simulate"
        return ("wrong-values" if _assert_failure(text) else "sim-failed"), text, "simulate"
    except TrackingError as exc:
        return ("sim-failed" if model.should_pass else "rejected"), f"{type(exc).__name__}: {exc}", "simulate"
    return ("pass" if model.should_pass else "accepted"), "", "simulate"


def _worker_main(argv: list[str]) -> int:
    """``python -m trackingbox.compliance --one NAME FILE true|false SUITE``: one model, JSON on stdout."""
    name, file, should, suite = argv
    model = TestModel(name, Path(file), should == "true")
    logging.basicConfig(level=logging.WARNING)
    with tempfile.TemporaryDirectory(prefix="tbx-compliance-") as tmp:
        try:
            outcome, message, stage = run_one(model, Path(suite), Path(tmp))
        except BaseException as exc:  # noqa: BLE001 - the point is to classify everything
            outcome, stage = "crashed", "compile"
            message = f"{type(exc).__name__}: {exc}\n" + "".join(traceback.format_exc(limit=-3))
    write_result({"outcome": outcome, "message": message, "stage": stage})
    return 0


def run_isolated(model: TestModel, suite: Path, timeout: float) -> ModelResult:
    """Run *model* in a fresh worker process with a time limit; never raises for the model's sake."""
    cmd = [sys.executable, "-m", "trackingbox.compliance", "--one", model.name, str(model.file),
           "true" if model.should_pass else "false", str(suite)]
    t0 = time.perf_counter()
    stage = "compile"
    data = run_worker(cmd, timeout)
    if data is None:
        outcome, message = "hang", f"no result after {timeout:g} s"
    else:
        outcome, message, stage = data["outcome"], data["message"], data.get("stage", stage)
    seconds = time.perf_counter() - t0
    message = message.strip()
    return ModelResult(model.name, model.section, model.should_pass, outcome, message[:4000],
                       round(seconds, 2), str(model.file), locations_in(message), stage)


def load_results(path: Path) -> dict[str, dict]:
    """Results already in a JSON-lines file, by model name (later lines win)."""
    done: dict[str, dict] = {}
    if path.is_file():
        for line in path.read_text(encoding="utf-8").splitlines():
            line = line.strip()
            if not line:
                continue
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line cut by an interruption
            done[rec["model"]] = rec
    return done


def table(results: list[dict]) -> str:
    """The per-section summary table."""
    sections = sorted({r["section"] for r in results})
    cols = [("pass", "pass", True), ("refused-construct", "ref:construct", True),
            ("refused-other", "ref:other", True), ("crashed", "crashed", None), ("hang", "hang", None),
            ("wrong-values", "wrong", True), ("sim-failed", "sim-fail", True),
            ("rejected", "inv:rejected", False), ("accepted", "inv:accepted", False)]
    head = (f"{'section':12s} {'valid':>5s} " + " ".join(f"{c[1]:>13s}" for c in cols) + f" {'invalid':>7s}"
            + f" {'loc:bad':>7s}")
    lines = [head, "-" * len(head)]
    verdicts = {r["model"]: location_verdict(r) for r in results}
    for sec in sections + ["TOTAL"]:
        rows = results if sec == "TOTAL" else [r for r in results if r["section"] == sec]
        count = Counter(r["outcome"] for r in rows)
        valid = sum(1 for r in rows if r["should_pass"])
        invalid = len(rows) - valid
        bad = sum(1 for r in rows if verdicts[r["model"]] not in (None, "ok"))
        lines.append(f"{sec:12s} {valid:5d} " + " ".join(f"{count.get(c[0], 0):13d}" for c in cols)
                     + f" {invalid:7d} {bad:7d}")
    refusals = sum(1 for v in verdicts.values() if v is not None)
    wrong = sorted((m, v) for m, v in verdicts.items() if v not in (None, "ok"))
    lines.append(f"loc:bad = compile-time refusals (of {refusals}) whose first position is missing, not inside "
                 "the model's own class in its own file, or on a line without the construct named")
    lines += [f"  {v:9s} {m}" for m, v in wrong]
    return "\n".join(lines)


def default_suite() -> Path:
    """``../shared/modelica-compliance/ModelicaCompliance`` beside the repository, or $TRACKINGBOX_COMPLIANCE."""
    env = config.get("compliance")
    if env:
        return Path(env)
    repo = Path(__file__).resolve().parents[2]
    return repo.parent / "shared" / "modelica-compliance" / "ModelicaCompliance"


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--one"]:
        return _worker_main(argv[1:])
    p = argparse.ArgumentParser(
        prog="scripts/compliance",
        description="Compile every test model of the Modelica compliance suite with the embedded backend, "
                    "simulate the valid ones, and print a table of outcomes per section.",
        epilog="examples:\n  scripts/compliance\n  scripts/compliance --match Arrays.Functions -j 1\n"
               "  scripts/compliance --resume --out compliance-out/results.jsonl",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--suite", type=Path, default=None, help="the suite's package directory "
                   "(default: ../shared/modelica-compliance/ModelicaCompliance)")
    p.add_argument("--out", type=Path, default=Path("compliance-out/results.jsonl"),
                   help="JSON-lines results file, written as models finish (default: %(default)s)")
    p.add_argument("-j", "--jobs", type=int, default=2, help="parallel worker processes (default: 2)")
    p.add_argument("--timeout", type=float, default=180.0, help="seconds per model (default: 180)")
    p.add_argument("--match", action="append", default=[], help="only models whose name contains this "
                   "(repeatable)")
    p.add_argument("--limit", type=int, default=None, help="at most this many models")
    p.add_argument("--resume", action="store_true", help="skip models already in --out")
    p.add_argument("--table", type=Path, default=None, metavar="RESULTS",
                   help="only print the table of an existing results file (JSON lines) and exit")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.table is not None:
        if not args.table.is_file():
            print(f"error: results file {args.table} not found", file=sys.stderr)
            return 2
        results = list(load_results(args.table).values())
        if args.match:
            results = [r for r in results if any(m in r["model"] for m in args.match)]
        print(table(results))
        return 0
    suite = (args.suite or default_suite()).resolve()
    if not (suite / "package.mo").is_file():
        print(f"error: compliance suite package {suite} not found (no package.mo); give --suite",
              file=sys.stderr)
        return 2
    models = discover(suite)
    if args.match:
        models = [m for m in models if any(s in m.name for s in args.match)]
    if args.limit is not None:
        models = models[: args.limit]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    done = load_results(args.out) if args.resume else {}
    if not args.resume:
        args.out.write_text("", encoding="utf-8")
    todo = [m for m in models if m.name not in done]
    log.info("%d test models (%d already done), %d jobs, %g s per model -> %s",
             len(models), len(models) - len(todo), args.jobs, args.timeout, args.out)
    lock = threading.Lock()
    t0 = time.perf_counter()
    signal.signal(signal.SIGTERM, interrupt)
    pool = ThreadPoolExecutor(max(1, args.jobs))
    try:
        with open(args.out, "a", encoding="utf-8") as fh:
            futures = {pool.submit(run_isolated, m, suite, args.timeout): m for m in todo}
            for k, fut in enumerate(as_completed(futures), 1):
                res = fut.result()
                with lock:
                    fh.write(json.dumps(res.to_json()) + "\n")
                    fh.flush()
                done[res.model] = res.to_json()
                log.info("[%d/%d] %-70s %-17s %6.1f s", k, len(todo), res.model, res.outcome, res.seconds)
    except KeyboardInterrupt:
        pool.shutdown(wait=False, cancel_futures=True)
        stop_workers()
        log.info("interrupted: the results so far are in %s (continue with --resume)", args.out)
        return 130
    pool.shutdown()
    names = {m.name for m in models}
    results = [r for n, r in done.items() if n in names]
    print(table(results))
    print(f"{len(results)} models in {time.perf_counter() - t0:.0f} s; per-model results in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
