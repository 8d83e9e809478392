"""Windows and initial state (issue 30, item 2): no FMU runs before the data's first sample; a run
without history starts from the FMU's own initial state or, asked for, its steady state; the warm-up is
shortened to the history that exists and the result says so; a hang in the warm-up says so.

Independent expectations: the first-order twin's steady state ``u/(1 + k tau)`` solved by hand, the
start times the stages ask of the FMU (recorded), and the crafted binary that hangs at a known call.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_casadi import build_casadi_fmu
from _fixtures_tracking import make_case
from trackingbox.errors import FMUError, SimulationError
from trackingbox.estimation import estimate
from trackingbox.fmu import FMUModel
from trackingbox.spec import load_spec
from trackingbox.testing import crafted as crafted_fmus
from trackingbox.testing.crafted import Misbehaviour
from trackingbox.testing.specs import first_order_spec
from trackingbox.tracking.runtime import track


@pytest.fixture
def starts(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """Every start time a run asks of an FMU in this process."""
    seen: list[float] = []
    original = FMUModel.stepper

    def stepper(self, *args, **kwargs):
        seen.append(float(kwargs.get("start_time", 0.0)))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(FMUModel, "stepper", stepper)
    return seen


def test_no_run_starts_before_the_first_sample_and_the_result_says_the_warm_up_was_shortened(
        first_order_fmu, tmp_path, starts):
    spec = load_spec(make_case(first_order_fmu, tmp_path / "case"))  # training [0, 3000), validation [3000, 6000)
    result = estimate(spec, seed=0, maxiter=2, popsize=6, warmup=3600.0, workers=1)
    assert starts and min(starts) == 0.0
    assert result.warmups == {"training": 0.0, "validation": 3000.0}  # the history there is: 3000 s of 3600
    assert result.shortened_warmups() == {"training": 0.0, "validation": 3000.0}
    note = result.warmup_note()
    assert "shortened" in note and "3600" in note and "the FMU's own initial state" in note
    assert result.to_json()["warmup"]["used"] == {"training": 0.0, "validation": 3000.0}


def test_a_window_with_enough_history_keeps_its_warm_up(first_order_fmu, tmp_path, starts):
    spec = load_spec(make_case(first_order_fmu, tmp_path / "case"))
    result = estimate(spec, seed=0, maxiter=1, popsize=6, warmup=1000.0, workers=1)
    assert result.warmups["validation"] == 1000.0 and "validation" not in result.shortened_warmups()
    assert 2000.0 in starts  # the validation window's run starts 1000 s before it


def test_steady_start_is_the_hand_solved_steady_state(first_order_fmu):
    with FMUModel(first_order_fmu) as m:
        for native in (True, False):
            st = m.stepper(parameters={"k": 0.004, "u": 55.0}, native=native)
            assert st.get(["y"])[0] == 38.0  # the FMU's own start value
            st.settle()
            assert st.get(["y"])[0] == pytest.approx(55.0 / (1.0 + 0.004 * 100.0), rel=1e-10)
            st.step(500.0)  # and it stays there
            assert st.get(["y"])[0] == pytest.approx(55.0 / 1.4, rel=1e-8)


def test_tracking_starts_from_the_steady_state_when_asked(first_order_fmu, tmp_path):
    case = make_case(first_order_fmu, tmp_path / "case")
    case.write_text(case.read_text() + '\n[data]\ninitial = "steady"\n')
    df = pd.read_csv(track(load_spec(case), out_dir=tmp_path / "out").csv)
    # the untracked twin (k = 0.003, u = 50) sits at its steady state from the first row on
    assert df["untracked:TI"].iloc[0] == pytest.approx(50.0 / 1.3, rel=1e-9)
    assert df["untracked:TI"].iloc[150] == pytest.approx(50.0 / 1.3, rel=1e-7)


def test_a_model_without_a_steady_state_is_refused_naming_the_state(tmp_path):
    fmu = build_casadi_fmu(tmp_path / "tank", "tank", variables=[
        ("u", ("input",), {"start": 1.0}),
        ("level", ("local", "continuous"), {"start": 2.0, "initial": "exact"}),
        ("y", ("output",), {}),
    ], equations=[("der(level)", "u - 0.5"), ("y", "level")])
    with FMUModel(fmu) as m:
        st = m.stepper(parameters={"u": 1.0})
        with pytest.raises(SimulationError) as err:
            st.settle()
        assert st.get(["y"])[0] == 2.0  # the states are left as they were
    text = str(err.value)
    assert "no steady state" in text and "level" in text and 'initial = "model"' in text and "\n" not in text


def test_co_simulation_cannot_start_steady(tmp_path):
    from trackingbox.testing.lag_fmu import build_lag_fmus

    cs = build_lag_fmus(tmp_path / "lag", ["cs"])["cs"]
    with FMUModel(cs) as m:
        st = m.stepper()
        with pytest.raises(FMUError, match='co-simulation.*initial = "model"'):
            st.settle()


def test_a_hang_in_the_warm_up_says_it_was_the_warm_up(tmp_path):
    """The crafted binary's 3rd fmi2DoStep never returns: the training window's run starts at 0 s, 600 s
    before the window, so that step is in its warm-up (the canary's step is in a process of its own)."""
    if not crafted_fmus.available():
        pytest.skip("crafted FMU binaries need a C compiler on Linux")
    fmu = crafted_fmus.build(tmp_path / "fmus", {"hang_step3": Misbehaviour(9, 4, nth=3)})["hang_step3"]
    root = tmp_path / "case"
    root.mkdir()
    (root / "measurements.csv").write_text("time,FI,TI\n" + "".join(f"{10.0 * i},1.0,1.0\n" for i in range(121)))
    spec = root / "spec.toml"
    spec.write_text(first_order_spec(twin=fmu.as_posix(), start=1.0, lower=0.5, upper=2.0, training=(600.0, 1200.0),
                                     validation=(0.0, 600.0)))
    env = {**os.environ, "TRACKINGBOX_FMU_TIMEOUT": "2"}
    for name in ("TRACKINGBOX_SUPERVISE", "TRACKINGBOX_WATCHDOG", "TRACKINGBOX_CANARY"):
        env.pop(name, None)
    exe = str(Path(sys.executable).parent / "trackingbox")
    proc = subprocess.run([exe, "estimate", str(spec), "--warmup", "600", "--workers", "1"], capture_output=True,
                          text=True, timeout=180, env=env)
    assert proc.returncode == 2, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, proc.stderr
    assert "did not return from fmi2DoStep within 2 s" in errors[0]
    assert "during the warm-up before the training window" in errors[0] and "t = 0 to 600 s" in errors[0]


def test_the_steady_state_matches_a_long_run_with_the_inputs_held(first_order_fmu):
    """What the benches used to do (a long pre-run with the inputs held) and the steady start agree."""
    with FMUModel(first_order_fmu) as m:
        st = m.stepper(parameters={"k": 0.006, "u": 47.0})
        st.settle()
        steady = float(st.get(["y"])[0])
        run = m.simulate(stop_time=20000.0, output_interval=1000.0, parameters={"k": 0.006, "u": 47.0},
                         outputs=["y"])
    assert steady == pytest.approx(float(run["y"].iloc[-1]), rel=1e-7)
    assert np.isfinite(steady)
