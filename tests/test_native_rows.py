"""The tracking loop's rows in C (``tbn_track_rows``, ``rows.NativeRows``; issue 12).

Independent expectations: the Python classes :class:`ScaledPI` and
:class:`StateCompensator` (the C laws must give the same floats, bit for bit,
on random sequences with holds, missing values, clamps and sub-steps), the
block's law integrated by scipy (``solve_ivp``) over one sample, and the
tracking loop's Python path (``TRACKINGBOX_NATIVE_ROWS=0``), whose
``tracking.csv``, ``result.json`` and checkpoint the C rows must reproduce byte
for byte: with holds, a tag going missing, a flow stoppage, state
compensation, sub-steps, checkpoints, a resumed run and a twin failing inside
a row.
"""
from __future__ import annotations

import ctypes
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_casadi import build_casadi_fmu
from _fixtures_tracking import K_TWIN, TANK_SPEC, TAU, make_case, native_unavailable
from test_controllers_roots import CASES, _clamped_by_solve_ivp, _law_from_zeros
from trackingbox.errors import SimulationError
from trackingbox.spec import load_spec
from trackingbox.tracking import rows as rows_module
from trackingbox.tracking import runtime
from trackingbox.tracking.controllers import Scaling, ScaledPI, StateCompensator

native = pytest.importorskip("trackingbox.native")


pytestmark = pytest.mark.skipif(native_unavailable() is not None,
                                reason=f"no native stepper on this machine: {native_unavailable()}")


# --------------------------------------------------------------------------- the laws

def _pi_state(c: ScaledPI) -> np.ndarray:
    sc = c.scaling
    return np.array([c.u, c.e_mem or 0.0, c.e_mem is not None, c.e_last or 0.0, c.e_last is not None,
                     c.hold_last, c.direction * c.kp, c.ti, c.te, sc.span, sc.p_min, sc.p_max, c.mode == "hold"],
                    dtype=float)


def _sc_state(c: StateCompensator) -> np.ndarray:
    return np.array([c.m, c.e_mem or 0.0, c.e_mem is not None, c.e_last or 0.0, c.e_last is not None,
                     c.hold_last, c.gain, c.ts, c.te, c.mode == "hold"], dtype=float)


def _ptr(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@pytest.mark.parametrize("seed", range(6))
def test_pi_law_in_c_is_scaled_pi_bit_for_bit(seed: int) -> None:
    # random setpoints and process values around the variable, holds, missing values, gains large enough
    # to reach both clamps, and the sub-steps' shorter spans: every value and the state after every call
    rng = np.random.default_rng(seed)
    lib = native.library()
    ts = 10.0
    kp, ti = float(rng.uniform(0.2, 8.0)), float(rng.uniform(5.0, 400.0))
    direction = int(rng.choice([-1, 1]))
    py = ScaledPI(Scaling(2.0, 7.0, span=float(rng.uniform(0.5, 20.0))), kp=kp, ti=ti, ts=ts,
                  direction=direction, p0=float(rng.uniform(2.0, 7.0)), interpolation="linear")
    state = _pi_state(py)
    clamped = 0
    for i in range(3000):
        sp = float(rng.normal(50.0, 3.0)) if rng.random() > 0.03 else math.nan
        pv = float(rng.normal(50.0, 3.0)) if rng.random() > 0.03 else math.nan
        hold = bool(rng.random() < 0.1)
        dt = float(rng.choice([ts, ts / 3.0, ts / 8.0, 2.0 * ts / 3.0]))
        want = py.update(sp, pv, hold=hold, dt=None if dt == ts else dt)
        got = lib.tbn_pi_linear(_ptr(state), sp, pv, int(hold), dt)
        assert got == want, (i, got, want)
        np.testing.assert_array_equal(state, _pi_state(py))
        clamped += py.u in (0.0, 100.0)
    assert clamped > 10  # the clamps were reached


@pytest.mark.parametrize("seed", range(3))
def test_compensator_in_c_is_state_compensator_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    lib = native.library()
    py = StateCompensator(float(rng.uniform(0.1, 10.0)), ts=10.0, interpolation="linear")
    state = _sc_state(py)
    for i in range(2000):
        meas = float(rng.normal(1.0, 0.1)) if rng.random() > 0.03 else math.nan
        sim = float(rng.normal(1.0, 0.1)) if rng.random() > 0.03 else math.nan
        hold = bool(rng.random() < 0.1)
        want = py.update(meas, sim, hold=hold)
        got = lib.tbn_comp_linear(_ptr(state), meas, sim, int(hold))
        assert got == want, (i, got, want)
        np.testing.assert_array_equal(state, _sc_state(py))


@pytest.mark.parametrize("f1, f2, te_frac, ti", CASES[:4])
@pytest.mark.parametrize("k, u0", [(20.0, 99.0), (20.0, 1.0), (-15.0, 0.5), (-15.0, 50.0)])
def test_pi_law_in_c_matches_solve_ivp(f1: float, f2: float, te_frac: float, ti: float, k: float, u0: float) -> None:
    # one sample of the block's clamped law with the error linear from e0 to e1 and the memory at m0
    # (rates with zero, one or two sign changes, bounds reached on the way), against scipy's integration
    ts, gain = 10.0, 1.5
    te = te_frac * ts
    e0, e1, m0 = _law_from_zeros(f1 * ts, f2 * ts, k, te, ti, ts)
    ref = _clamped_by_solve_ivp(u0, gain, ti, e0, e1, m0, ts, te)
    # span 100 and p in 0..100: the error in % is the setpoint and the parameter is u
    state = np.array([u0, m0, 1.0, e0, 1.0, 0.0, gain, ti, te, 100.0, 0.0, 100.0, 0.0])
    got = native.library().tbn_pi_linear(_ptr(state), e1, 0.0, 0, ts)
    assert got == pytest.approx(ref, abs=1e-6)


def test_compensator_in_c_matches_the_closed_form() -> None:
    # dm/dt = K (e - eMem)/Te, deMem/dt = (e - eMem)/Te with e = e0 + s t: over one sample
    # m gains K (e - eMem) integrated, = K ((e1 - eMem(Ts)) - (e0 - m0)) + K s Ts ... written out by hand:
    # e - eMem = s Te + (e0 - m0 - s Te) exp(-t/Te), so m(Ts) - m(0) = K (s Ts + (e0 - m0 - s Te)(1 - exp(-Ts/Te)))
    K, ts, te = 3.0, 10.0, 1.0
    e0, e1, m0 = 0.2, -0.1, 0.05
    s = (e1 - e0) / ts
    want = 0.7 + K * (s * ts + (e0 - m0 - s * te) * (1.0 - math.exp(-ts / te)))
    state = np.array([0.7, m0, 1.0, e0, 1.0, 0.0, K, ts, te, 0.0])
    assert native.library().tbn_comp_linear(_ptr(state), e1, 0.0, 0) == pytest.approx(want, rel=1e-14)
    assert state[1] == pytest.approx(e1 - s * te + (m0 - e0 + s * te) * math.exp(-ts / te), rel=1e-14)


# --------------------------------------------------------------------------- tracking runs

#: the steps the last _run's C rows left to Python
INTERRUPTED: list[tuple[int, int, int]] = []


def _run(spec_path: Path, out: Path, monkeypatch: pytest.MonkeyPatch, rows: bool, **kw):
    """``track`` with the rows in C (*rows*) or on the Python path: (result, rows C wrote, error)."""
    monkeypatch.setenv(rows_module.NATIVE_ROWS_ENV, "1" if rows else "0")
    written = [0]
    original = rows_module.NativeRows.run
    INTERRUPTED.clear()

    def counting(self, loop, k, k_stop):  # type: ignore[no-untyped-def]
        out_ = original(self, loop, k, k_stop)
        written[0] += out_[0]
        if out_[1] is not None:
            INTERRUPTED.append(out_[1][2])  # (twin, sub-step, code) of a step C left to Python
        return out_

    monkeypatch.setattr(rows_module.NativeRows, "run", counting)
    resume = kw.pop("resume_after", None)
    try:
        if resume is not None:
            first = runtime.track(load_spec(spec_path), out_dir=out, max_steps=resume, **kw)
            assert not first.complete
            result = runtime.track(load_spec(spec_path), out_dir=out, resume=True, **kw)
        else:
            result = runtime.track(load_spec(spec_path), out_dir=out, **kw)
        return result, written[0], None
    except SimulationError as exc:
        return None, written[0], str(exc)


def _same_outputs(a: Path, b: Path) -> None:
    assert (a / "tracking.csv").read_bytes() == (b / "tracking.csv").read_bytes()
    ra, rb = (json.loads((d / "result.json").read_text()) for d in (a, b))
    for r in (ra, rb):
        r.pop("seconds"), r.pop("csv")
    assert ra == rb
    ca, cb = (json.loads((d / "checkpoint.json").read_text()) for d in (a, b))
    assert ca == cb


@pytest.fixture(scope="module")
def fmu(first_order_fmu: Path) -> Path:
    return first_order_fmu


CASE_SETTINGS = {
    "plain": ({}, {}),
    "missing tag": ({"nan_span": (2500.0, 3100.0), "max_gap": 120.0}, {}),
    "stoppage": ({"stoppage": (1000.0, 1500.0), "settle": 200.0}, {}),
    "sub-steps and checkpoints": ({}, {"substeps": 3, "checkpoint_every": 7}),
    "no untracked twin": ({"nan_span": (2500.0, 2600.0)}, {"untracked": False, "substeps": 2}),
    "restart path": ({}, {"carry": 0.0, "substeps": 2}),
}


@pytest.mark.parametrize("name", list(CASE_SETTINGS))
def test_rows_in_c_write_the_python_paths_bytes(name: str, fmu: Path, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    case_kw, track_kw = CASE_SETTINGS[name]
    spec = make_case(fmu, tmp_path / "case", **case_kw)
    py, py_rows, _ = _run(spec, tmp_path / "py", monkeypatch, False, **track_kw)
    c, c_rows, _ = _run(spec, tmp_path / "c", monkeypatch, True, **track_kw)
    assert py_rows == 0 and c_rows > 0.5 * c.steps  # the rows ran in C (the rest: those that need Python)
    _same_outputs(tmp_path / "py", tmp_path / "c")
    assert (py.restarts, py.carried) == (c.restarts, c.carried)
    assert [(e.time, e.kind, e.message) for e in py.events] == [(e.time, e.kind, e.message) for e in c.events]


def test_rows_in_c_resume_as_the_uninterrupted_python_run(fmu: Path, tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    spec = make_case(fmu, tmp_path / "case", stoppage=(1000.0, 1500.0))
    _run(spec, tmp_path / "py", monkeypatch, False, substeps=3, checkpoint_every=25)
    _, c_rows, _ = _run(spec, tmp_path / "c", monkeypatch, True, substeps=3, checkpoint_every=25, resume_after=125)
    assert c_rows > 300
    _same_outputs(tmp_path / "py", tmp_path / "c")


def test_rows_in_c_with_state_compensation(tank_fmu, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from trackingbox.fmu import FMUModel

    t = np.arange(0.0, 3001.0, 10.0)
    with FMUModel(tank_fmu(1.0)) as m:
        sim = m.simulate(stop_time=3000.0, output_interval=10.0,
                         inputs=pd.DataFrame({"time": t, "u": 50.0 + 0 * t, "q": 1.0 + 0.2 * (t > 1500.0)}),
                         parameters={"k": 0.004, "x": 50.0 / 1.4}, outputs=["y", "level"])
    case = tmp_path / "case"
    case.mkdir()
    rng = np.random.default_rng(3)
    pd.DataFrame({"time": t, "FI": 50.0, "QI": 1.0 + 0.2 * (t > 1500.0),
                  "TI": sim["y"] + rng.normal(0.0, 0.02, t.size),
                  "LI": sim["level"] + rng.normal(0.0, 0.002, t.size)}).to_csv(case / "measurements.csv", index=False)
    (case / "twin.fmu").write_bytes(tank_fmu(1.2).read_bytes())
    (case / "spec.toml").write_text(TANK_SPEC + "[tracking]\nhold_until = 200.0\n")
    py, _, _ = _run(case / "spec.toml", tmp_path / "py", monkeypatch, False, substeps=2, checkpoint_every=40)
    c, c_rows, _ = _run(case / "spec.toml", tmp_path / "c", monkeypatch, True, substeps=2, checkpoint_every=40)
    assert c_rows > 250
    _same_outputs(tmp_path / "py", tmp_path / "c")
    assert py.carried > 0 and (py.restarts, py.carried) == (c.restarts, c.carried)


def test_a_twin_failing_inside_a_row_ends_as_on_the_python_path(fmu: Path, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    # the twin's derivative is NaN while its input is below 1 (the square root of a negative number): in the stoppage
    # the input is 0, CVODE fails inside a row that C started; the step, the recovery from the saved
    # states, the cold start and the error that ends the run are the Python path's, and so are the rows
    failing = build_casadi_fmu(tmp_path / "fmu", "hx1nan", constants={"TAU": TAU}, variables=[
        ("k", ("parameter", "tunable"), {"start": K_TWIN, "min": 0.0, "max": 0.1}),
        ("u", ("input",), {"start": 50.0}),
        ("x", ("local", "continuous"), {"start": 38.0, "initial": "exact"}),
        ("y", ("output",), {}),
    ], equations=[("der(x)", "(u - x) / TAU - k * x + 1e-9 * (u - 1.0) ** 0.5"), ("y", "x")])
    spec = make_case(fmu, tmp_path / "case", stoppage=(2000.0, 2500.0))  # the plant: the regular model
    (spec.parent / "twin.fmu").write_bytes(failing.read_bytes())
    _, _, py_error = _run(spec, tmp_path / "py", monkeypatch, False, substeps=2)
    _, c_rows, c_error = _run(spec, tmp_path / "c", monkeypatch, True, substeps=2)
    assert py_error is not None and c_error == py_error
    assert c_rows > 150
    assert INTERRUPTED and INTERRUPTED[0][2] == native.CVODE_FAILED  # the failure happened inside C's rows
    assert (tmp_path / "py" / "tracking.csv").read_bytes() == (tmp_path / "c" / "tracking.csv").read_bytes()


@pytest.mark.compile
@pytest.mark.parametrize("bench, twin", [("heat-exchanger", "TrackingBox.Benches.HeatExchanger"),
                                         ("heat-production", "TrackingBox.Benches.HeatProduction")])
def test_rows_in_c_on_the_benches(bench: str, twin: str, fmu_cache, tmp_path: Path,
                                  monkeypatch: pytest.MonkeyPatch) -> None:
    # one hour of each bench with hand-set pairs (the heat exchanger's kht; heat production's pressure loop,
    # whose within-sample gain asks for sub-steps, and a temperature loop) and heat production's three
    # level compensations: the rows in C write the Python path's bytes
    from trackingbox.benches import make_bench
    from trackingbox.spec import PairSpec, write_pairs

    case = make_bench(bench, tmp_path / "case", seed=0, hours=1.0, plant_fmu=fmu_cache(f"{twin}.Plant"),
                      twin_fmu=fmu_cache(f"{twin}.Twin"))
    pairs = [PairSpec("TI-102", "hx.kht", gain=-0.0237, time_constant=64.0, lambda_=1.0)] \
        if bench == "heat-exchanger" else \
        [PairSpec("PI-100", "Pipe100.k", gain=1088604.0, time_constant=204.0, lambda_=1.0),
         PairSpec("TI-301", "HEX300.kht", gain=-0.0206, time_constant=85.0, lambda_=1.0)]
    spec = write_pairs(case.spec, pairs)
    py, _, _ = _run(spec.path, tmp_path / "py", monkeypatch, False, checkpoint_every=100)
    c, c_rows, _ = _run(spec.path, tmp_path / "c", monkeypatch, True, checkpoint_every=100)
    assert c_rows > 0.9 * c.steps
    _same_outputs(tmp_path / "py", tmp_path / "c")
    assert (py.restarts, py.carried) == (c.restarts, c.carried)


def test_the_untracked_twin_failing_inside_a_row_is_dropped_as_on_the_python_path(
        fmu: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # a derivative that is NaN in the stoppage (input 0) while k < 0.0035: the untracked twin (k = 0.003)
    # fails there for good, the tracked one (k near the plant's 0.004 by then) does not. The untracked
    # twin's step inside C's row is finished in Python, fails again, is dropped, and the rows go on in C
    # without it: the same bytes and events as the Python path
    failing = build_casadi_fmu(tmp_path / "fmu", "hx1nank", constants={"TAU": TAU}, variables=[
        ("k", ("parameter", "tunable"), {"start": K_TWIN, "min": 0.0, "max": 0.1}),
        ("u", ("input",), {"start": 50.0}),
        ("x", ("local", "continuous"), {"start": 38.0, "initial": "exact"}),
        ("y", ("output",), {}),
    ], equations=[("der(x)", "(u - x) / TAU - k * x + 1e-9 * ((u - 1.0) + 1e4 * (k - 0.0035)) ** 0.5"),
                  ("y", "x")])
    spec = make_case(fmu, tmp_path / "case", stoppage=(2000.0, 2500.0))
    (spec.parent / "twin.fmu").write_bytes(failing.read_bytes())
    py, _, py_error = _run(spec, tmp_path / "py", monkeypatch, False, substeps=2)
    c, c_rows, c_error = _run(spec, tmp_path / "c", monkeypatch, True, substeps=2)
    assert py_error is None and c_error is None
    assert "untracked-abandoned" in [e.kind for e in c.events]
    assert INTERRUPTED and INTERRUPTED[0][0] == 1  # the untracked twin's step, inside C's rows
    assert c_rows > 0.8 * c.steps
    _same_outputs(tmp_path / "py", tmp_path / "c")
    assert [(e.time, e.kind, e.message) for e in py.events] == [(e.time, e.kind, e.message) for e in c.events]


def test_rows_are_formatted_as_the_csv_module_writes_them() -> None:
    # random bit patterns (every exponent, subnormals), values near the repr's switch to exponents,
    # integers, signed zeros, infinities, NaN, and mode flags: the text csv.writer makes, byte for byte
    import csv
    import io

    rng = np.random.default_rng(5)
    bits = rng.integers(0, 2**63, size=(400, 7), dtype=np.int64).view(np.float64)
    special = np.array([0.0, -0.0, math.inf, -math.inf, math.nan, 1.0, 1e16, 1e15, 1e-5, 1e-4, 0.1, 5e-324,
                        2.0**60, 123456789.0, -1.5, 2.0**51 + 0.25, 1.7976931348623157e308])
    cols = [bits, rng.normal(0.0, 1e3, size=(400, 3)), np.round(rng.normal(0.0, 100.0, size=(400, 2))),
            rng.choice(special, size=(400, 4)), rng.integers(0, 2, size=(400, 2)).astype(float)]
    values = np.concatenate(cols, axis=1)
    want = io.StringIO(newline="")
    writer = csv.writer(want)
    for row in values.tolist():
        writer.writerow(row[:-2] + ["hold" if m else "auto" for m in row[-2:]])
    got = native.format_rows(values, 2)
    assert got is not None and got == want.getvalue()
