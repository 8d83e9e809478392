"""A run from the twin's steady state never starts inside a stoppage (``[data] initial = "steady"``).

The evaporator train's twin has no steady state with its feed stopped and its steam on (its liquor
boils dry and its equations leave their range): a validation warm-up that began in a stoppage ended in
"array must not contain infs or NaNs". The small model here has the same property (made up: a tank
held at mass ``M``, fed at ``F`` with dry solids ``C_F``, concentrated by boiling at a rate that grows
as its dry solids ``c`` approach 1)::

    M dc/dt = F (C_F - c) + E0 (2 - c) / sqrt(1 - c)

Fed (F = 1 kg/s) it settles at the lower root of the right-hand side (found here with ``brentq``);
with the feed stopped the right-hand side is positive for every c below 1 (no root, not even far out):
it concentrates without bound, and its rates are
NaN beyond c = 1 (its equations hold only below c = 1, as the train's liquor properties hold only below
dry solids 1). The plant's data
are made with scipy's Radau integrator, not with the FMU; the expected start times are worked by hand.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from trackingbox.errors import SimulationError
from trackingbox.estimation import load_windows
from trackingbox.simulation.windows import problem_from_spec, simulate_window, warmup_used
from trackingbox.spec import load_spec

M, C_F, E0 = 1000.0, 0.2, 0.1
DT = 10.0

SPEC = """\
twin = "{fmu}"
measurements = "measurements.csv"
sample_time = 10.0

[inputs]
"FI-1" = "F"

[outputs]
"QI-1" = "y"

[[parameters]]
name = "E0"
start = 0.1
min = 0.05
max = 0.2

[windows]
training = [0.0, 3600.0]
validation = [4000.0, 7200.0]

[data]
initial = "steady"
stoppage = {{ tag = "FI-1", below = 0.05, settle = 300.0 }}
"""


@pytest.fixture(scope="module")
def tank(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from _fixtures_casadi import build_casadi_fmu

    return build_casadi_fmu(tmp_path_factory.mktemp("tank"), "tank", constants={"M": M, "C_F": C_F}, variables=[
        ("E0", ("parameter", "tunable"), {"start": E0}),
        ("F", ("input",), {"start": 1.0}),
        ("c", ("local", "continuous"), {"start": 0.3, "initial": "exact"}),
        ("y", ("output",), {}),
    ], equations=[("der(c)", "(F * (C_F - c) + E0 * (2 - c) / (1 - c) ** 0.5) / M"), ("y", "c")])


def _rate(c: float, f: float) -> float:
    return (f * (C_F - c) + E0 * (2.0 - c) / np.sqrt(1.0 - c)) / M


def _case(directory: Path, fmu: Path, stopped: tuple[float, float]) -> Path:
    """Two hours of data, the feed stopped over *stopped*; the plant settled at its first inputs."""
    t = np.arange(0.0, 7200.0 + DT / 2, DT)
    feed = np.where((t >= stopped[0]) & (t < stopped[1]), 0.0, 1.0)
    start = brentq(lambda c: _rate(c, feed[0]), 0.2, 0.6) if feed[0] > 0 else 0.3
    # the twin interpolates its input linearly between samples: so does this plant
    run = solve_ivp(lambda s, c: [_rate(c[0], float(np.interp(s, t, feed)))], (0.0, t[-1]), [start],
                    method="Radau", rtol=1e-10, atol=1e-12, t_eval=t, max_step=DT / 2)
    assert run.success and np.all(run.y[0] < 1.0)
    directory.mkdir(parents=True, exist_ok=True)
    pd.DataFrame({"time": t, "FI-1": feed, "QI-1": run.y[0]}).to_csv(directory / "measurements.csv", index=False)
    spec = directory / "spec.toml"
    spec.write_text(SPEC.format(fmu=fmu.as_posix()), encoding="utf-8")
    return spec


def test_the_model_has_no_steady_state_with_the_feed_stopped_and_says_so(tank: Path, tmp_path: Path) -> None:
    from trackingbox.fmu import FMUModel

    model = FMUModel(tank)
    try:
        # fed, the steady state is the root of the balance
        fed = model.simulate(start_time=0.0, stop_time=10.0, output_interval=10.0, outputs=["y"], initial="steady",
                             inputs=pd.DataFrame({"time": [0.0, 10.0], "F": [1.0, 1.0]}))
        assert float(fed["y"].iloc[0]) == pytest.approx(brentq(lambda c: _rate(c, 1.0), 0.2, 0.6), rel=1e-6)
        with pytest.raises(SimulationError) as caught:
            model.simulate(start_time=3300.0, stop_time=3310.0, output_interval=10.0, outputs=["y"], initial="steady",
                           inputs=pd.DataFrame({"time": [3300.0, 3310.0], "F": [0.0, 0.0]}))
    finally:
        model.close()
    text = str(caught.value)
    assert "no steady state at t = 3300 s" in text and "derivative of c became NaN or infinite" in text
    assert "array must not contain" not in text


def test_a_warmup_that_would_start_in_a_stoppage_starts_before_it(tank: Path, tmp_path: Path) -> None:
    spec = load_spec(_case(tmp_path, tank, (3000.0, 3600.0)))
    # the validation window [4000, 7200) s with 1000 s of warm-up would start at 3000 s, the stoppage's
    # first sample: it starts the rule's 300 s settle time before, at 2700 s (1300 s of warm-up)
    training, validation = load_windows(spec, warmup=1000.0)
    assert validation.time[0] == 2700.0 and warmup_used(validation) == 1300.0
    assert training.time[0] == 0.0  # the training window starts at the first sample, running: as it was
    assert load_windows(spec, warmup=500.0)[1].time[0] == 2700.0  # from 3500 s, in the same stoppage
    # a warm-up that starts where the plant runs is left as asked: after the stoppage, or before it
    assert load_windows(spec, warmup=300.0)[1].time[0] == 3700.0
    assert load_windows(spec, warmup=1500.0)[1].time[0] == 2500.0
    # the run goes through the stoppage as the plant did and meets the plant's data in the window
    problem = problem_from_spec(spec, warmup=1000.0)
    out = simulate_window(problem, validation, problem.start)["QI-1"]
    plant = pd.read_csv(tmp_path / "measurements.csv").set_index("time")["QI-1"]
    inside = validation.time >= validation.start
    assert np.max(np.abs(out[inside] - plant.loc[validation.time[inside]].to_numpy())) <= 2e-4


def test_a_warmup_in_a_stoppage_that_began_earlier_walks_back_past_it(tank: Path, tmp_path: Path) -> None:
    # stopped 2000-3600 s: a warm-up from 3000 s starts 300 s before 2000 s, at 1700 s
    spec = load_spec(_case(tmp_path, tank, (2000.0, 3600.0)))
    assert load_windows(spec, warmup=1000.0)[1].time[0] == 1700.0
    # a warm-up of 4000 s would start at the first sample, where the plant runs: as asked
    assert load_windows(spec, warmup=4000.0)[1].time[0] == 0.0


def test_data_that_begin_stopped_get_a_clear_error(tank: Path, tmp_path: Path) -> None:
    spec = load_spec(_case(tmp_path, tank, (0.0, 600.0)))
    training, _ = load_windows(spec, warmup=1000.0)
    assert training.time[0] == 0.0  # no running sample before: the start stays
    problem = problem_from_spec(spec, warmup=1000.0)
    with pytest.raises(SimulationError, match=r"no steady state at t = 0 s .*derivative of c became NaN"):
        simulate_window(problem, training, problem.start)
