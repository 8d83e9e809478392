"""A slow state an effect adds (a scale) is carried from the training run into the validation run.

The twin: a fast process state ``T`` (``der(T) = (u - T)/TAU``, settles in seconds) and a scale ``R``
that grows with the input and washes off over ``TW`` (``der(R) = K u - R/TW``, start 0), seen in
``y = T + R``. With a constant input ``u`` the plant started clean at t = 0 has
``R(t) = K u TW (1 - exp(-t/TW))`` (the expectation, written here from the equation, not from a run).
A validation run that starts inside the training run must start ``R`` where that run had it; a steady
start must not settle ``R`` to its equilibrium ``K u TW``, nor restart it at 0.
"""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest

from trackingbox.diagnose.library import load_effects, read_effect
from trackingbox.errors import SpecError
from trackingbox.simulation.models import close_models
from trackingbox.simulation.windows import Problem, WindowData, carried_names, simulate_window
from trackingbox.spec import load_spec, write_spec

TAU, K, TW, U = 5.0, 1.0e-3, 1000.0, 2.0
DT = 10.0


@pytest.fixture(scope="module")
def scale_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from _fixtures_casadi import build_casadi_fmu

    return build_casadi_fmu(tmp_path_factory.mktemp("carry"), "scale", constants={"TAU": TAU, "TW": TW}, variables=[
        ("k", ("parameter", "tunable"), {"start": K, "min": 0.0, "max": 0.01}),
        ("u", ("input",), {"start": U}),
        ("T", ("local", "continuous"), {"start": 0.0, "initial": "exact"}),
        ("R", ("local", "continuous"), {"start": 0.0, "initial": "exact"}),
        ("y", ("output",), {}),
    ], equations=[("der(T)", "(u - T) / TAU"), ("der(R)", "k * u - R / TW"), ("y", "T + R")])


def _window(name: str, first: float, start: float, stop: float) -> WindowData:
    time = np.arange(first, stop, DT)
    lead = int(round((start - first) / DT))
    measured = np.where(time >= start, 0.0, np.nan)
    return WindowData(name, start, stop, time, {"u": np.full(time.size, U)}, {"Y": measured}, lead)


def _problem(fmu: Path, carry: tuple[str, ...]) -> Problem:
    return Problem(twin=fmu, names=("k",), start=np.array([K]), lower=np.array([0.0]), upper=np.array([0.01]),
                   fixed={}, outputs={"Y": "y"}, sample_time=DT, warmup=1000.0, initial="steady", carry=carry)


def scale(t: np.ndarray | float) -> np.ndarray:
    """The plant's scale from a clean surface at t = 0."""
    return K * U * TW * (1.0 - np.exp(-np.asarray(t, dtype=float) / TW))


def test_validation_run_starts_the_scale_where_the_training_run_had_it(scale_fmu):
    training = _window("training", 0.0, 0.0, 3000.0)
    validation = _window("validation", 2000.0, 3000.0, 6000.0)   # its run begins 1000 s into training's
    both = (training, validation)
    problem = _problem(scale_fmu, ("R",))
    try:
        y_train = simulate_window(problem, training, [K], history=both)
        y_valid = simulate_window(problem, validation, [K], history=both)
        # without the history the validation run starts R at its own start value (0), held, not settled
        y_alone = simulate_window(problem, validation, [K])
        # without the carry a steady start settles R to its equilibrium K u TW
        y_settled = simulate_window(_problem(scale_fmu, ()), validation, [K])
    finally:
        close_models()
    # T settles to u at once (steady start); R from 0 at t = 0: the analytic trajectory on both windows
    assert y_train["Y"] == pytest.approx(U + scale(training.time), abs=2e-4)
    assert y_valid["Y"] == pytest.approx(U + scale(validation.time), abs=2e-4)
    assert y_valid["Y"][0] == pytest.approx(U + K * U * TW * (1 - math.exp(-2.0)), abs=2e-4)
    assert y_alone["Y"] == pytest.approx(U + scale(validation.time - validation.time[0]), abs=2e-4)
    assert y_settled["Y"] == pytest.approx(np.full(validation.time.size, U + K * U * TW), abs=2e-4)


def test_a_run_no_earlier_run_covers_starts_the_state_at_its_start(scale_fmu):
    training = _window("training", 0.0, 0.0, 2000.0)
    validation = _window("validation", 3000.0, 3000.0, 5000.0)   # a gap in the data: nothing to carry from
    problem = _problem(scale_fmu, ("R",))
    try:
        y_valid = simulate_window(problem, validation, [K], history=(training, validation))
    finally:
        close_models()
    assert y_valid["Y"] == pytest.approx(U + scale(validation.time - 3000.0), abs=2e-4)


def test_carried_names_are_states_of_the_twin():
    def state(name):
        return NS(variable=NS(derivative=NS(name=name)))

    info = NS(model_description=NS(derivatives=[state("T"), state("s_R[1]"), state("s_R[2]"), state("s_R2")]))
    problems: list[str] = []
    assert carried_names(info, ("s_R",), problems, "twin") == ("s_R[1]", "s_R[2]") and not problems
    assert carried_names(info, ("T", "s_Q"), problems, "twin") == ("T",)
    assert len(problems) == 1 and "s_Q" in problems[0] and "twin" in problems[0]


def test_the_spec_keeps_data_carry(tmp_path):
    (tmp_path / "m.csv").write_text("time,U,Y\n0,1,1\n")
    (tmp_path / "spec.toml").write_text(
        'twin = "twin.fmu"\nmeasurements = "m.csv"\nsample_time = 10.0\n[inputs]\nU = "u"\n[outputs]\nY = "y"\n'
        '[[parameters]]\nname = "k"\nstart = 0.001\nmin = 0.0\nmax = 0.01\n'
        '[windows]\ntraining = [0.0, 10.0]\nvalidation = [10.0, 20.0]\n'
        '[data]\ninitial = "steady"\ncarry = ["scale_R"]\n')
    spec = load_spec(tmp_path / "spec.toml", check_files=False)
    assert spec.data.carry == ("scale_R",)
    again = load_spec(write_spec(spec, tmp_path / "again.toml"), check_files=False)
    assert again.data.carry == ("scale_R",) and again.data.initial == "steady"
    (tmp_path / "bad.toml").write_text((tmp_path / "spec.toml").read_text().replace('["scale_R"]', '"scale_R"'))
    with pytest.raises(SpecError, match="carry"):
        load_spec(tmp_path / "bad.toml", check_files=False)


def test_effect_entries_declare_their_carried_states(tmp_path):
    effects = load_effects()
    assert effects["soluble-scale"].carried == ("R",)
    assert effects["sensor-lag"].carried == ()   # a lag settles in minutes: no history
    bad = tmp_path / "bad-scale"
    bad.mkdir()
    src = effects["soluble-scale"].folder
    (bad / "effect.toml").write_text((src / "effect.toml").read_text()
                                     .replace('id = "soluble-scale"', 'id = "bad-scale"')
                                     .replace('carried = ["R"]', 'carried = ["R-1"]'))
    (bad / "patch.mo.jinja").write_text((src / "patch.mo.jinja").read_text())
    with pytest.raises(SpecError, match="carried"):
        read_effect(bad)
