#!/usr/bin/env python3
"""Fuzz trackingbox's commands with seeded bad inputs and tabulate what a user meets.

Each case is one bad input (a CSV, a spec, an FMU archive, a Modelica source or
a set of command-line options) and one command run on it with a time limit. The cases are written
by :mod:`_fuzz_cases`; this module runs and judges them.
Its outcome is one of:

``refused``       exit 2, exactly one ``error:`` line, bounded, naming the thing
                  and where (the file, option or name the case is about);
``refused-vague`` exit 2 and one ``error:`` line, but too long or not naming where;
``accepted``      exit 0 (the input was bad in a way the command may accept), or exit 1
                  without an error line (a documented negative result: pair found no pairs);
``accepted-bad``  exit 0 on an input that must be refused;
``traceback``     a Python traceback reached the user;
``signal``        the process was killed by a signal (a foreign binary crashed);
``hang``          the time limit passed;
``half-written``  a refusal that left files in the output location or the temp dir;
``other``         any other exit code or a refusal with several ``error:`` lines.

Cases that only exercise Python run in a child forked from this (warm) process,
which calls ``trackingbox.cli.main`` with stdout/stderr redirected to files: as
faithful as the console script (same exceptions, exit codes and output) at a
fraction of its start-up. Cases whose input carries foreign native code (crafted
FMU binaries, archives, Modelica sources) run through the console script
``trackingbox`` as real subprocesses. Every child gets its own temp directory
(checked empty afterwards) and an address-space limit.

Exit status: 0 when there are no tracebacks, signals, hangs or half-written
outputs; 1 otherwise.

Examples::

    scripts/fuzz                         # 1000 cases, seed 1, two at a time
    scripts/fuzz --cases 200 --seed 7 -j 1 --kinds spec,csv
    scripts/fuzz --cases 1000 --seed 1 --keep /tmp/fuzz --show traceback,signal
"""
from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import os
import random
import resource
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import textwrap
import time
import zipfile
from collections.abc import Callable
from pathlib import Path

from trackingbox.testing import crafted
from trackingbox.testing.specs import first_order_spec

from _fuzz_cases import KINDS, MAKERS, MODEL, Case, Maker, plan

M = crafted.Misbehaviour
ROOT = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent / "trackingbox"

#: modules the commands import lazily: imported once in this process, before the children fork
WARM = ("trackingbox.spec", "trackingbox.data", "trackingbox.fmu", "trackingbox.estimation",
        "trackingbox.tracking.runtime", "trackingbox.report", "trackingbox.analysis.pair_stage",
        "trackingbox.generate.generator", "trackingbox.validate", "trackingbox.compiler", "fmpy.simulation",
        "fmpy.fmi2", "fmpy.fmi3", "fmpy.sundials", "matplotlib.pyplot")
OUTCOMES = ("refused", "refused-vague", "accepted", "accepted-bad", "traceback", "signal", "hang",
            "half-written", "other")
FAILING = ("traceback", "signal", "hang", "half-written")
MAX_ERROR_LINE = 1000       # characters of the error line
MAX_STDERR = 6000           # characters of the whole stderr on a refusal
MEMORY_LIMIT = 3 << 30      # address space per case (bytes)
FMU_TIMEOUT = 10.0          # s an FMI call may take in the canary and under the watchdog (TRACKINGBOX_FMU_TIMEOUT)
FILE_LIMIT = 1 << 30        # largest file a case may write (bytes): a zip bomb cannot fill the disk


# --------------------------------------------------------------------------- the base case


@dataclasses.dataclass
class Base:
    """The valid inputs every case mutates."""

    dir: Path
    fmu: Path
    model: Path
    csv_rows: list[tuple[float, float, float]]
    bomb: Path
    many: Path
    crafted: dict[str, Path]

    def csv_text(self, rows: list[tuple[float, float, float]] | None = None) -> str:
        rows = self.csv_rows if rows is None else rows
        return "time,FI,TI\n" + "".join(f"{t:g},{u:.6g},{y:.6g}\n" for t, u, y in rows)

    def spec_text(self) -> str:
        return first_order_spec(twin=self.fmu.as_posix(), start=0.005, lower=0.001, upper=0.05,
                                training=(0.0, 600.0), validation=(600.0, 1200.0), fixed={"tau": 60.0},
                                pair={"gain": -2000.0, "time_constant": 50.0}, hold_until=50.0)


def _measurements(n: int = 121) -> list[tuple[float, float, float]]:
    rng = random.Random(0)
    rows, x = [], 38.0
    for i in range(n):
        t = 10.0 * i
        u = 50.0 + (10.0 if t >= 400 else 0.0)
        rows.append((t, u, x + rng.gauss(0, 0.02)))
        for _ in range(10):
            x += (u - x) / 60.0 - 0.004 * x
    return rows


def build_base(work: Path, log: Callable[[str], None]) -> Base:
    """Compile the twin, write the measurements, the zip bomb, the many-entry archive, the crafted binaries."""
    base = work / "base"
    base.mkdir(parents=True, exist_ok=True)
    model = base / "FuzzTwin.mo"
    model.write_text(MODEL)
    fmu = base / "twin.fmu"
    if not fmu.exists():
        from trackingbox.compiler import compile_model

        t0 = time.perf_counter()
        compile_model(model, "FuzzTwin", backend="embedded", output=fmu)
        log(f"compiled the base twin in {time.perf_counter() - t0:.0f} s")
    bomb = base / "bomb.fmu"
    if not bomb.exists():
        _write_bomb(fmu, bomb)
    many = base / "many.fmu"
    if not many.exists():
        _write_many(fmu, many)
    crafted = build_crafted(base / "crafted", log)
    return Base(dir=base, fmu=fmu, model=model, csv_rows=_measurements(), bomb=bomb, many=many, crafted=crafted)


def _write_bomb(fmu: Path, out: Path, size: int = 2 << 30) -> None:
    """The real FMU plus one entry that inflates to *size* bytes of zeros (a few MB compressed)."""
    tmp = out.with_suffix(".part")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as dst:
        for item in src.infolist():
            dst.writestr(item, src.read(item))
        chunk = bytes(1 << 24)
        with dst.open("resources/zeros.bin", "w", force_zip64=True) as fh:
            for _ in range(size // len(chunk)):
                fh.write(chunk)
    tmp.replace(out)


def _write_many(fmu: Path, out: Path, n: int = 120_000) -> None:
    tmp = out.with_suffix(".part")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as dst:
        for item in src.infolist():
            dst.writestr(item, src.read(item))
        for i in range(n):
            dst.writestr(f"resources/f{i}.txt", b"")
    tmp.replace(out)


# --------------------------------------------------------------------------- crafted binaries

#: crafted FMU name -> its misbehaviour (see trackingbox.testing.crafted)
CRAFTED = {
    "segv_load": M(1, 1), "abort_load": M(1, 2), "exit0_load": M(1, 3), "hang_load": M(1, 4),
    "segv_instantiate": M(2, 1), "abort_instantiate": M(2, 2), "exit0_instantiate": M(2, 3),
    "hang_instantiate": M(2, 4), "exit3_instantiate": M(2, 5), "segv_setup": M(3, 1),
    "segv_exitinit": M(4, 1), "segv_getreal": M(5, 1), "bus_getreal": M(5, 6), "segv_dostep": M(6, 1),
    "hang_dostep": M(6, 4), "exit0_dostep": M(6, 3), "segv_free": M(7, 1),
    "segv_getreal_late": M(8, 1, nth=4),  # past the canary's reads
    "hang_dostep_late": M(9, 4, nth=5),   # past the canary's step: the watchdog's case
    "well_behaved": M(),
}


def build_crafted(out: Path, log: Callable[[str], None]) -> dict[str, Path]:
    """One FMI 2 co-simulation FMU per misbehaviour, plus a truncated and a garbage shared library."""
    made = crafted.build(out, CRAFTED)
    # a truncated shared library: the mapping ends inside the file's declared segments
    trunc = out / "truncated_so.fmu"
    if not trunc.exists():
        data = (out / "well_behaved.so").read_bytes()
        crafted.package(trunc, "truncated_so", data[: len(data) // 3])
    made["truncated_so"] = trunc
    garbage = out / "garbage_so.fmu"
    if not garbage.exists():
        crafted.package(garbage, "garbage_so", random.Random(5).randbytes(5000))
    made["garbage_so"] = garbage
    log(f"crafted {len(made)} FMUs with misbehaving binaries")
    return made


# --------------------------------------------------------------------------- running

def _snapshot(paths: list[Path]) -> dict[str, tuple[int, int]]:
    seen: dict[str, tuple[int, int]] = {}
    for root in paths:
        if not root.exists():
            continue
        for dirpath, dirnames, filenames in os.walk(root):
            for name in dirnames + filenames:
                p = os.path.join(dirpath, name)
                try:
                    st = os.lstat(p)
                except OSError:
                    continue
                seen[p] = (st.st_mtime_ns, st.st_size) if not stat.S_ISDIR(st.st_mode) else (0, 0)
    return seen


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    resource.setrlimit(resource.RLIMIT_FSIZE, (FILE_LIMIT, FILE_LIMIT))


class Running:
    """One case in flight: a forked child or a subprocess, with its capture files."""

    def __init__(self, case: Case, casedir: Path, logs: Path) -> None:
        self.case = case
        self.casedir = casedir
        self.tmp = logs / f"{case.id:05d}.tmp"
        self.tmp.mkdir(parents=True, exist_ok=True)
        self.stdout = logs / f"{case.id:05d}.out"
        self.stderr = logs / f"{case.id:05d}.err"
        self.before = _snapshot([casedir, self.tmp])
        self.t0 = time.monotonic()
        self.pid = 0
        self.proc: subprocess.Popen[bytes] | None = None
        env = dict(os.environ, TMPDIR=str(self.tmp), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
                   TRACKINGBOX_FMU_TIMEOUT=str(FMU_TIMEOUT))
        if case.subprocess:
            with open(self.stdout, "wb") as out, open(self.stderr, "wb") as err:
                self.proc = subprocess.Popen([str(BIN), *case.argv], stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                             env=env, cwd=casedir, preexec_fn=_limits, start_new_session=True)
            self.pid = self.proc.pid
        else:
            self.pid = os.fork()
            if self.pid == 0:  # the child: run the command as the console script would
                try:
                    os.setsid()
                    _limits()
                    os.environ.update(env)
                    tempfile.tempdir = None
                    os.chdir(casedir)
                    fd_out = os.open(self.stdout, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
                    fd_err = os.open(self.stderr, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
                    os.dup2(fd_out, 1)
                    os.dup2(fd_err, 2)
                    devnull = os.open(os.devnull, os.O_RDONLY)
                    os.dup2(devnull, 0)
                    sys.stdout = open(1, "w", closefd=False)
                    sys.stderr = open(2, "w", closefd=False)
                    import logging
                    for h in list(logging.root.handlers):
                        logging.root.removeHandler(h)
                    from trackingbox.cli import main
                    try:
                        rc = main(case.argv)
                    except SystemExit as exc:
                        code = exc.code
                        rc = code if isinstance(code, int) else (0 if code is None else 1)
                        if not isinstance(code, int) and code is not None:
                            print(code, file=sys.stderr)
                    except BaseException:  # what the interpreter does with an uncaught exception
                        import traceback
                        traceback.print_exc()
                        rc = 1
                    import atexit
                    atexit._run_exitfuncs()  # what interpreter shutdown runs (weakref finalizers: temp dirs)
                    sys.stdout.flush()
                    sys.stderr.flush()
                    os._exit(int(rc) & 0xFF)
                finally:
                    os._exit(120)

    def poll(self) -> int | None:
        """The wait status once the case has finished, else None."""
        if self.proc is not None:
            if self.proc.poll() is None:
                return None
            rc = self.proc.returncode
            return (-rc) if rc < 0 else (rc << 8)  # as a wait status
        pid, status = os.waitpid(self.pid, os.WNOHANG)
        return None if pid == 0 else status

    def kill(self) -> None:
        with contextlib_suppress():
            os.killpg(self.pid, signal.SIGKILL)
        if self.proc is not None:
            self.proc.wait()
        else:
            with contextlib_suppress():
                os.waitpid(self.pid, 0)


class contextlib_suppress:  # noqa: N801 - small local helper, no import in the forked path
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> bool:
        return exc[0] is not None and issubclass(exc[0], (OSError, ChildProcessError))  # type: ignore[arg-type]


def judge(run: Running, status: int | None, hung: bool) -> None:
    case = run.case
    case.seconds = time.monotonic() - run.t0
    err = run.stderr.read_text(errors="replace") if run.stderr.exists() else ""
    after = _snapshot([run.casedir, run.tmp])
    changed = sorted(p for p, v in after.items() if run.before.get(p) != v)
    if hung:
        case.outcome, case.detail = "hang", f"no end after {case.timeout:g} s"
        return
    assert status is not None
    if os.WIFSIGNALED(status):
        sig = signal.Signals(os.WTERMSIG(status)).name
        case.outcome, case.detail = "signal", f"killed by {sig}"
        return
    code = os.WEXITSTATUS(status)
    errors = [ln for ln in err.splitlines() if ln.startswith("error:") or ": error:" in ln[:60]]
    if "Traceback (most recent call last)" in err:
        last = [ln for ln in err.strip().splitlines() if ln.strip()][-1:] or ["exit 1"]
        case.outcome, case.detail = "traceback", last[0][:300]
        return
    if code == 1 and not errors:  # a negative result the command documents (pair: no pairs found)
        case.outcome, case.detail = "accepted", "exit 1 (a documented negative result)"
        return
    if code == 0:
        case.outcome = "accepted-bad" if case.must_refuse else "accepted"
        case.detail = "exit 0"
        return
    if code != 2:
        case.outcome, case.detail = "other", f"exit {code}: {err.strip()[:300]}"
        return
    if changed:
        case.outcome = "half-written"
        case.detail = f"{len(changed)} new or changed: " + ", ".join(os.path.relpath(p, run.casedir.parent)
                                                                      for p in changed[:3])
        return
    if len(errors) != 1:
        case.outcome, case.detail = "other", f"{len(errors)} error lines: {err.strip()[:300]}"
        return
    line = errors[0]
    case.detail = line[:300]
    # an option is named with or without its dashes (a stage names its setting 'popsize')
    names = any(h and (h.lower() in err.lower() or (h.startswith("--") and f"{h[2:].replace('-', '_')} "
                                                     in err.lower())) for h in case.hints) or not case.hints
    if len(line) > MAX_ERROR_LINE or len(err) > MAX_STDERR or not names:
        case.outcome = "refused-vague"
        why = "too long" if len(line) > MAX_ERROR_LINE or len(err) > MAX_STDERR else "names none of " + \
            ", ".join(repr(h[:30]) for h in case.hints)
        case.detail = f"{why}: {line[:240]}"
        return
    case.outcome = "refused"


def run_all(cases: list[Case], root: Path, logs: Path, jobs: int, progress: bool) -> None:
    pending = collections.deque(cases)
    running: list[Running] = []
    done = 0
    t0 = time.monotonic()
    while pending or running:
        while pending and len(running) < jobs:
            case = pending.popleft()
            running.append(Running(case, root / f"{case.id:05d}", logs))
        time.sleep(0.01)
        for run in list(running):
            status = run.poll()
            hung = status is None and time.monotonic() - run.t0 > run.case.timeout
            if status is None and not hung:
                continue
            if hung:
                run.kill()
            judge(run, status, hung)
            running.remove(run)
            done += 1
            if progress and (done % 25 == 0 or done == len(cases)):
                print(f"\r{done}/{len(cases)} cases, {time.monotonic() - t0:.0f} s", end="", file=sys.stderr,
                      flush=True)
    if progress:
        print(file=sys.stderr)


# --------------------------------------------------------------------------- report

def table(cases: list[Case]) -> str:
    kinds = [k for k in KINDS if any(c.kind == k for c in cases)]
    counts = {k: collections.Counter(c.outcome for c in cases if c.kind == k) for k in kinds}
    width = max(len(o) for o in OUTCOMES)
    lines = [f"{'outcome':<{width}} " + " ".join(f"{k:>8}" for k in kinds) + f" {'total':>8}"]
    for o in OUTCOMES:
        row = [counts[k][o] for k in kinds]
        lines.append(f"{o:<{width}} " + " ".join(f"{n:>8}" for n in row) + f" {sum(row):>8}")
    totals = [sum(counts[k].values()) for k in kinds]
    lines.append(f"{'cases':<{width}} " + " ".join(f"{n:>8}" for n in totals) + f" {sum(totals):>8}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="fuzz", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=textwrap.dedent(__doc__.split("Examples::")[1]))
    ap.add_argument("--cases", type=int, default=1000, help="number of cases (default 1000)")
    ap.add_argument("--seed", type=int, default=1, help="seed of the case generator (default 1)")
    ap.add_argument("-j", "--jobs", type=int, default=2, help="cases run at once (default 2)")
    ap.add_argument("--kinds", default=",".join(KINDS), help=f"comma-separated subset of {','.join(KINDS)}")
    ap.add_argument("--keep", type=Path, default=None, help="work in DIR and keep it (default: a temp dir)")
    ap.add_argument("--show", default=",".join(FAILING + ("accepted-bad", "refused-vague", "other")),
                    help="outcomes whose cases are listed after the table")
    ap.add_argument("--json", type=Path, default=None, help="write every case and its outcome to this file")
    args = ap.parse_args(argv)
    if args.cases < 1 or args.jobs < 1:
        ap.error("--cases and --jobs must be >= 1")
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        ap.error(f"unknown kind(s) {', '.join(unknown)}; choose from {', '.join(KINDS)}")
    if not BIN.exists():
        ap.error(f"no console script {BIN}: install trackingbox in this environment")

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    work = args.keep or Path(tempfile.mkdtemp(prefix="trackingbox-fuzz-"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        t0 = time.perf_counter()
        cpu0 = os.times()
        base = build_base(work, log)
        import importlib

        import trackingbox.cli  # warm the forked children: what the commands import, imported once
        trackingbox.cli.build_parser()
        for module in WARM:
            importlib.import_module(module)

        rng = random.Random(args.seed)
        root = work / f"cases-{args.seed}"
        if root.exists():
            _rmtree(root)
        maker = Maker(base, root, rng)
        cases = [MAKERS[kind](maker, i) for i, kind in enumerate(plan(args.cases, kinds, rng))]
        logs = work / f"logs-{args.seed}"
        if logs.exists():
            _rmtree(logs)
        logs.mkdir()
        log(f"{len(cases)} cases in {work} ({sum(c.subprocess for c in cases)} through the console script)")
        run_all(cases, root, logs, args.jobs, progress=True)
        wall = time.perf_counter() - t0
        cpu = os.times()
        print(table(cases))
        used = (cpu.children_user + cpu.children_system + cpu.user + cpu.system
                - cpu0.children_user - cpu0.children_system - cpu0.user - cpu0.system)
        print(f"\n{len(cases)} cases, seed {args.seed}, -j {args.jobs}: {wall:.0f} s wall, {used:.0f} s CPU")
        show = {s.strip() for s in args.show.split(",")}
        listed = [c for c in cases if c.outcome in show]
        if listed:
            print()
            for c in sorted(listed, key=lambda c: (c.outcome, c.name)):
                print(f"{c.outcome:13s} #{c.id:<5d} {c.name:40s} {c.detail[:200]}")
                print(f"{'':13s}        trackingbox {' '.join(_quote(a) for a in c.argv)[:300]}")
        if args.json:
            args.json.write_text(json.dumps([dataclasses.asdict(c) for c in cases], indent=1))
        failing = sum(c.outcome in FAILING for c in cases)
        return 1 if failing else 0
    finally:
        if args.keep is None:
            _rmtree(work)


def _quote(a: str) -> str:
    import shlex
    a = a if len(a) < 120 else a[:60] + "..." + a[-20:]
    return shlex.quote(a.replace("\x00", "\\0"))


def _rmtree(path: Path) -> None:
    def onerror(func: Callable[..., object], p: str, exc: object) -> None:
        with contextlib_suppress():
            os.chmod(os.path.dirname(p), 0o755)
            os.chmod(p, 0o755)
            func(p)
    for dirpath, dirnames, _ in os.walk(path):
        for name in dirnames:
            with contextlib_suppress():
                os.chmod(os.path.join(dirpath, name), 0o755)
    shutil.rmtree(path, onerror=onerror)


if __name__ == "__main__":
    sys.exit(main())
