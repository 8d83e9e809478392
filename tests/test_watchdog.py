"""The per-call watchdog (issue 13): an FMI call that hangs in the middle of a run becomes one error line.

The canary bounds loading, instantiation, initialisation and the first step; a
binary that hangs on a later ``fmi2DoStep`` is caught by
:class:`trackingbox.supervise.Watchdog` in the supervised command. The crafted
binaries are tiny FMI 2 co-simulation libraries built with gcc (as
``scripts/_fuzz.py`` builds them) whose ``fmi2DoStep`` hangs, sleeps once, or
sleeps a little on every call. The expectations are the binaries' own
behaviour: ``fmi2GetReal`` returns 1.0, the Nth ``fmi2DoStep`` does not return.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from trackingbox.fmu import FMUModel
from trackingbox.supervise import Watchdog, timeout_message
from trackingbox.testing import crafted as crafted_fmus
from trackingbox.testing.crafted import Misbehaviour
from trackingbox.testing.specs import first_order_spec

#: name -> misbehaviour (trackingbox.testing.crafted): the 20th fmi2DoStep never returns; every
#: fmi2DoStep sleeps 30 ms; the 3rd sleeps 2 s and returns
CRAFTED = {"hang_step20": Misbehaviour(9, 4, nth=20), "slow_steps": Misbehaviour(6, 7),
           "slow_step3": Misbehaviour(9, 8, nth=3), "well_behaved": Misbehaviour()}


EXE = str(Path(sys.executable).parent / "trackingbox")


@pytest.fixture(scope="module")
def crafted(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    if not crafted_fmus.available():
        pytest.skip("crafted FMU binaries need a C compiler on Linux")
    return crafted_fmus.build(tmp_path_factory.mktemp("watchdog"), CRAFTED)


def _case(root: Path, fmu: Path) -> Path:
    """A spec for *fmu* with 121 measurement rows every 10 s (the values matter little: y is 1.0)."""
    root.mkdir(parents=True)
    (root / "measurements.csv").write_text(
        "time,FI,TI\n" + "".join(f"{10.0 * i},1.0,1.0\n" for i in range(121)))
    spec = root / "spec.toml"
    spec.write_text(first_order_spec(twin=fmu.as_posix(), start=1.0, lower=0.5, upper=2.0, training=(0.0, 600.0),
                                     validation=(600.0, 1200.0), pair={"gain": -1.0, "time_constant": 50.0}))
    return spec


def _run(argv: list[str], tmp: Path, timeout: str) -> tuple[subprocess.CompletedProcess[str], float]:
    """The console script (supervised, watchdog on) with its own temp dir."""
    tmp.mkdir()
    env = {**os.environ, "TRACKINGBOX_FMU_TIMEOUT": timeout, "TMPDIR": str(tmp)}
    for name in ("TRACKINGBOX_SUPERVISE", "TRACKINGBOX_WATCHDOG", "TRACKINGBOX_CANARY"):
        env.pop(name, None)
    t0 = time.monotonic()
    proc = subprocess.run([EXE, *argv], capture_output=True, text=True, timeout=120, env=env)
    return proc, time.monotonic() - t0


def test_a_hang_on_the_20th_step_is_one_timeout_line_exit_2_and_nothing_left(
        crafted: dict[str, Path], tmp_path: Path) -> None:
    """The canary passes (it takes one step); the 20th fmi2DoStep of the run never returns."""
    spec = _case(tmp_path / "case", crafted["hang_step20"])
    out = tmp_path / "run" / "track"
    proc, seconds = _run(["track", str(spec), "--out", str(out)], tmp_path / "tmp", "2")
    assert proc.returncode == 2, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert errors == ["error: the FMU's binary (hang_step20.fmu) did not return from fmi2DoStep within 2 s "
                      "(TRACKINGBOX_FMU_TIMEOUT)"]
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "run").exists()  # the output directory the run was creating is gone
    assert list((tmp_path / "tmp").iterdir()) == []  # so are the extraction and the supervisor's files
    assert seconds < 60  # start-up + 2 s + one poll; generous for a loaded machine


def test_a_long_run_of_short_calls_is_not_a_timeout(crafted: dict[str, Path], tmp_path: Path) -> None:
    """150 steps of 30 ms each (4.5 s in all) with a 2 s limit per call: the run completes unchanged."""
    out = tmp_path / "result.csv"
    proc, seconds = _run(["simulate", str(crafted["slow_steps"]), "--set", "u=1", "--stop", "150", "--step", "1",
                          "-o", str(out)], tmp_path / "tmp", "2")
    assert proc.returncode == 0, proc.stderr
    assert "error" not in proc.stderr
    rows = out.read_text().splitlines()
    assert rows[0].split(",")[0] == "time" and len(rows) == 1 + 151  # t = 0 ... 150
    assert all(float(r.split(",")[-1]) == 1.0 for r in rows[1:])  # the binary's fmi2GetReal returns 1.0
    assert seconds >= 150 * 0.03  # the calls really took their time (the limit per call, not per run)


def test_a_normal_tracking_run_with_the_watchdog_on_is_unaffected(crafted: dict[str, Path], tmp_path: Path) -> None:
    spec = _case(tmp_path / "case", crafted["well_behaved"])
    out = tmp_path / "track"
    proc, _ = _run(["track", str(spec), "--out", str(out)], tmp_path / "tmp", "2")
    assert proc.returncode == 0, proc.stderr
    assert "error" not in proc.stderr
    rows = (out / "tracking.csv").read_text().splitlines()
    assert len(rows) >= 1 + 120  # one row per sample of the 1200 s of measurements (or more with the start)


def test_the_watchdog_names_a_stuck_call_once_and_ignores_short_ones(crafted: dict[str, Path]) -> None:
    """In-process, with a callback that only records: the 3rd fmi2DoStep sleeps 2 s against a 0.5 s limit."""
    fired: list[tuple[str, str, float]] = []
    with FMUModel(crafted["slow_step3"]) as model, \
            Watchdog(lambda *a: fired.append(a), timeout=0.5, poll=0.05):
        result = model.simulate(stop_time=6.0, output_interval=1.0, parameters={"u": 1.0})
    assert list(result["y"]) == [1.0] * 7  # the slow call returned and the run went on
    assert fired == [("fmi2DoStep", str(crafted["slow_step3"]), 0.5)]

    fired.clear()
    with FMUModel(crafted["slow_steps"]) as model, \
            Watchdog(lambda *a: fired.append(a), timeout=0.5, poll=0.05):
        model.simulate(stop_time=40.0, output_interval=1.0, parameters={"u": 1.0})  # 40 calls of 30 ms
    assert fired == []


def test_the_timeout_message() -> None:
    assert timeout_message("fmi3DoStep", "/a/b/twin.fmu", 60.0) == (
        "the FMU's binary (twin.fmu) did not return from fmi3DoStep within 60 s (TRACKINGBOX_FMU_TIMEOUT)")
    assert timeout_message("fmi2GetReal", "", 2.5).startswith("foreign native code (an FMU's binary) did not")


# --------------------------------------------------------------------------- the native stepper's calls

#: fmi3GetContinuousStateDerivatives calls after which the hanging twin's never returns: past the
#: canary's first step, inside the tracking run's rows (which call the FMU from C, under no fmpy frame)
HANG_AFTER = 400


def _hanging_twin(fmu: Path, out: Path, after: int) -> Path:
    """*fmu* (a CasADi-made FMI 3 model exchange FMU with its sources) rebuilt so that its
    fmi3GetContinuousStateDerivatives never returns after *after* calls."""
    import shutil
    import zipfile

    import fmpy

    work = out.with_suffix(".d")
    with zipfile.ZipFile(fmu) as z:
        z.extractall(work)
    [wrap] = (work / "sources").glob("*_wrap.c")
    text = wrap.read_text()
    head = "fmi3Status fmi3GetContinuousStateDerivatives("
    at = text.index("{", text.index(head)) + 1
    wrap.write_text("#include <unistd.h>\n" + text[:at]
                    + f"\n  {{ static long calls; if (++calls > {after}) for (;;) pause(); }}" + text[at:])
    [lib] = (work / "binaries").rglob("*.so")
    sources = sorted(str(p) for p in (work / "sources").glob("*.c"))
    subprocess.run([os.environ.get("CC", "gcc"), "-O1", "-shared", "-fPIC", "-I",
                    str(Path(fmpy.__file__).parent / "c-code"), "-I", str(work / "sources"), "-o", str(lib),
                    *sources, "-lm"], check=True, capture_output=True, text=True)
    with zipfile.ZipFile(out, "w") as z:
        for path in sorted(work.rglob("*")):
            if path.is_file():
                z.write(path, path.relative_to(work).as_posix())
    shutil.rmtree(work)
    return out


@pytest.fixture
def native_library() -> None:
    """Skip (saying why) where the native stepper cannot be built: nothing then calls FMUs from C."""
    from trackingbox import native

    try:
        native.library()
    except native.NativeUnavailable as exc:
        pytest.skip(f"the native stepper cannot be built here: {exc}")


def test_a_hang_inside_the_native_stepper_is_one_timeout_line_exit_2(first_order_fmu: Path, tmp_path: Path,
                                                                    native_library: None) -> None:
    """The tracking rows run in C (trackingbox.native) and call the FMU from there: no fmpy frame is on
    the stack while they do. The twin's 400th fmi3GetContinuousStateDerivatives never returns."""
    from _fixtures_tracking import make_case

    if not crafted_fmus.available():
        pytest.skip("the hanging twin is rebuilt with a C compiler on Linux")
    spec = make_case(first_order_fmu, tmp_path / "case", stop=3000.0)
    _hanging_twin(first_order_fmu, tmp_path / "case" / "twin.fmu", HANG_AFTER)
    out = tmp_path / "run" / "track"
    proc, seconds = _run(["track", str(spec), "--out", str(out)], tmp_path / "tmp", "2")
    assert proc.returncode == 2, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert errors == ["error: the FMU's binary (twin.fmu) did not return from fmi3GetContinuousStateDerivatives "
                      "within 2 s (TRACKINGBOX_FMU_TIMEOUT)"], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "run").exists()
    assert seconds < 60


def test_the_native_call_count_moves_with_every_call_and_is_even_between_them(first_order_fmu: Path,
                                                                            native_library: None) -> None:
    """What the watchdog reads: an even count after a stepper's calls returned, moved on by them."""
    from trackingbox import native
    from trackingbox.fmu import NativeStepper

    with FMUModel(first_order_fmu) as model:
        st = model.stepper(start_time=0.0, parameters={"k": 0.003})
        assert isinstance(st, NativeStepper)
        seq0, _ = native.fmi_call()
        st.step(100.0)
        seq1, name = native.fmi_call()
    assert seq0 % 2 == 0 and seq1 % 2 == 0
    # at least a set of the states and a derivative per right-hand side, each counted twice (in, out)
    assert seq1 - seq0 >= 4
    assert name.startswith("fmi3")


# --------------------------------------------------------------------------- the watchdog and the imports

#: A process in which the import of ``trackingbox.native`` is held between the moment its (empty) module
#: object is in ``sys.modules`` and the moment its code runs, whenever a watchdog thread exists then: the
#: window in which a watchdog that imports or looks the module up finds it partially initialised.
RACE = r'''
import importlib.machinery, sys, threading

errors = []
threading.excepthook = lambda a: errors.append(repr(a.exc_value))
polled = threading.Event()


class Hold:
    def find_spec(self, name, path, target=None):
        if name != "trackingbox.native":
            return None
        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        run = spec.loader.exec_module

        def exec_module(module):
            if any(t.name == "trackingbox-fmu-watchdog" for t in threading.enumerate()):
                polled.wait(30.0)  # the watchdog looks at the module while it is empty
            run(module)

        spec.loader.exec_module = exec_module
        return spec


sys.meta_path.insert(0, Hold())
from trackingbox.supervise import Watchdog

looks = []
original = Watchdog._native_call


def counted():
    try:
        return original()
    finally:
        looks.append(1)
        if len(looks) >= 3:
            polled.set()


Watchdog._native_call = staticmethod(counted)
dog = Watchdog(lambda *a: None, timeout=60.0, poll=0.01).start()
import trackingbox.native  # noqa: E402,F401 - the command's own import, as the estimate stage makes it
polled.wait(30.0)
alive = dog._thread.is_alive()
dog.stop()
print("errors", errors, "alive", alive, "looks", len(looks) >= 3)
'''


def test_the_watchdog_never_sees_the_native_library_half_imported() -> None:
    """A watchdog thread started before the command imports ``trackingbox.native`` kept looking at it.

    It read the module from ``sys.modules`` while the main thread was still importing it and died with
    ``AttributeError: partially initialized module 'trackingbox.native' has no attribute 'fmi_call'``; a
    hang inside the native stepper then went unseen for the whole run. The supervisor imports the library
    at module level now, so by the time any watchdog exists the module is whole.
    """
    proc = subprocess.run([sys.executable, "-c", RACE], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "errors [] alive True looks True"
