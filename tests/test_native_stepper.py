"""The native model-exchange stepper (issue 12): the same runs as the Python path, without Python in a step.

Independent expectations: the Python path (``ModelExchangeStepper``: fmpy's
CVodeSolver with a Python right-hand side) on the bench twins, the closed-form
solution of the first-order twin, and the Python path's error texts.

The agreement bound on the bench twins: both paths run the same CVODE library
with the same method, tolerances (``rtol = 1e-6``, ``atol = rtol * nominal``),
largest step and stop times, on right-hand sides that make the same FMU calls
with the same interpolated inputs. Any difference can only come from the
floating-point order of the input interpolation, which a local error test at
``rtol`` absorbs; we therefore ask for agreement within ``rtol`` of each
variable's magnitude plus ``rtol`` times its range, which is one local error
tolerance of the integrator (measured: the trajectories are bit-identical).
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_casadi import build_casadi_fmu
from _fixtures_tracking import K_TWIN, TAU, native_unavailable
from trackingbox.errors import AssertionFailed, FMUError, SimulationError
from trackingbox.fmu import FMUModel, ModelExchangeStepper

native = pytest.importorskip("trackingbox.native")
from trackingbox.fmu import NativeStepper  # noqa: E402

RTOL = 1e-6


pytestmark = pytest.mark.skipif(native_unavailable() is not None,
                                reason=f"no native stepper on this machine: {native_unavailable()}")


# --------------------------------------------------------------------------- bench twins

BENCH_TWINS = {
    "heat-exchanger": "TrackingBox.Benches.HeatExchanger.Twin",
    "heat-production": "TrackingBox.Benches.HeatProduction.Twin",
}


@pytest.fixture(scope="module")
def bench_cases(fmu_cache, tmp_path_factory: pytest.TempPathFactory):
    """Each bench's 1-hour case on the session's compiled twin: (twin FMU, base values, input table)."""
    from trackingbox.benches import make_bench
    from trackingbox.data import MeasurementView
    from trackingbox.spec import load_spec

    cases = {}

    def get(name: str):
        if name not in cases:
            plant = BENCH_TWINS[name].replace(".Twin", ".Plant")
            case = make_bench(name, tmp_path_factory.mktemp(name), seed=0, hours=1.0,
                              plant_fmu=fmu_cache(plant), twin_fmu=fmu_cache(BENCH_TWINS[name]))
            spec = load_spec(case.spec)
            base = {p.name: p.start for p in spec.parameters}
            base.update(spec.fixed)
            inputs = MeasurementView.from_spec(spec).inputs
            tunable = [p.name for p in spec.parameters]
            cases[name] = (spec.twin, base, inputs, tunable)
        return cases[name]

    return get


def _run(fmu: Path, base: dict, inputs: pd.DataFrame, tunable: list[str], *, use_native: bool):
    """Step 1800 s in 10 s steps; every 60 s move the first tunable parameter by 1 %, carried or restarted."""
    with FMUModel(fmu) as model:
        st = model.stepper(parameters=base, inputs=inputs, carry=True, native=use_native)
        assert type(st) is (NativeStepper if use_native else ModelExchangeStepper)
        names = model.info.outputs + st.state_names
        read = st.reader(names)
        rows = [read()]
        p = tunable[0]
        value = float(base.get(p, st.get([p])[0]))
        for k, t in enumerate(np.arange(10.0, 1801.0, 10.0)):
            if k % 6 == 5:
                value *= 1.01
                st.set({p: value}, restart=(k % 12 == 5))
            st.step(float(t))
            rows.append(read())
        return np.array(rows), (st.restarts, st.carried), names


@pytest.mark.compile
@pytest.mark.parametrize("bench", sorted(BENCH_TWINS))
def test_native_reproduces_the_python_path_on_the_bench_twins(bench_cases, bench: str) -> None:
    fmu, base, inputs, tunable = bench_cases(bench)
    ours, counts, names = _run(fmu, base, inputs, tunable, use_native=True)
    ref, ref_counts, _ = _run(fmu, base, inputs, tunable, use_native=False)
    assert np.all(np.isfinite(ref))
    # half the changes carried, half restarted, on both paths alike
    assert counts == ref_counts and counts[0] > 5 and counts[1] > 5
    span = ref.max(axis=0) - ref.min(axis=0)
    bound = RTOL * np.abs(ref).max(axis=0) + RTOL * span
    diff = np.abs(ours - ref).max(axis=0)
    worst = int(np.argmax(diff / np.maximum(bound, 1e-300)))
    assert np.all(diff <= bound), (names[worst], diff[worst], bound[worst])


def _run_advance(fmu: Path, base: dict, inputs: pd.DataFrame, tunable: list[str]):
    """_run's schedule through NativeStepper.advance: one C call per step for the set, the step and the reads."""
    with FMUModel(fmu) as model:
        st = model.stepper(parameters=base, inputs=inputs, carry=True, native=True)
        names = tuple(model.info.outputs + st.state_names)
        rows = [st.reader(names)()]
        states = []
        p = tunable[0]
        value = float(base.get(p, st.get([p])[0]))
        for k, t in enumerate(np.arange(10.0, 1801.0, 10.0)):
            change = {}
            if k % 6 == 5:
                value *= 1.01
                change = {p: value}
            x, y = st.advance(change, float(t), names, restart=(k % 12 == 5))
            assert st.time == float(t)
            rows.append(y)
            states.append(x)
        return np.array(rows), np.array(states), (st.restarts, st.carried)


@pytest.mark.compile
@pytest.mark.parametrize("bench", sorted(BENCH_TWINS))
def test_advance_is_set_step_and_reads_in_one_call(bench_cases, bench: str) -> None:
    # tbn_advance makes the calls set(), step(), get_continuous_states() and a reader make, in their order:
    # the same run bit for bit as those methods on the native stepper, and the Python path's within _run's bound
    fmu, base, inputs, tunable = bench_cases(bench)
    ours, states, counts = _run_advance(fmu, base, inputs, tunable)
    ref, ref_counts, _ = _run(fmu, base, inputs, tunable, use_native=True)
    py, py_counts, _ = _run(fmu, base, inputs, tunable, use_native=False)
    assert counts == ref_counts == py_counts
    assert np.array_equal(ours, ref)  # same calls, same order: identical
    nx = states.shape[1]
    assert np.array_equal(states, ref[1:, -nx:])  # the states read back equal the state variables
    span = py.max(axis=0) - py.min(axis=0)
    assert np.all(np.abs(ours - py).max(axis=0) <= RTOL * np.abs(py).max(axis=0) + RTOL * span)


def test_advance_follows_the_closed_form_and_takes_the_python_path_where_it_must(first_order_fmu: Path) -> None:
    # k stepped at 100 s (carried; the names to read given as a list, which advance does not cache), then a set
    # that changes nothing (no restart, no carry): x by hand, segment by segment, as in the step/set test
    with FMUModel(first_order_fmu, tolerance=1e-9) as model:
        st = model.stepper(start_time=0.0, parameters={"k": K_TWIN}, carry=True, native=True)
        x, y = st.advance({}, 100.0, ("y",))
        x_ref = _closed_form(38.0, K_TWIN, 100.0)
        assert y.tolist() == pytest.approx([x_ref], rel=1e-7) and x.tolist() == pytest.approx([x_ref], rel=1e-7)
        x, y = st.advance({"k": 0.004}, 200.0, ["y", "k"], restart=False)
        x_ref = _closed_form(x_ref, 0.004, 100.0)
        assert y.tolist() == pytest.approx([x_ref, 0.004], rel=1e-7)
        assert (st.carried, st.restarts) == (1, 0)
        x, y = st.advance({"k": 0.004}, 300.0, ("y",), restart=True)  # equal to the last set: nothing to set
        assert (st.carried, st.restarts) == (1, 0)
        assert y.tolist() == pytest.approx([_closed_form(x_ref, 0.004, 100.0)], rel=1e-7)
        assert st.holds({"k": 0.004}) and not st.holds({"k": 0.005})
        # a step back in time is step()'s error
        with pytest.raises(SimulationError, match="back in time"):
            st.advance({}, 250.0, ("y",))


def _blow_up_advance(st) -> None:
    st.advance({}, 0.5, ("y",))
    st.advance({"p": 1.0}, 0.6, ("y",), restart=False)
    for t in np.arange(0.7, 3.0, 0.1):
        st.advance({}, float(t), ("y",))


def test_advance_fails_as_the_python_path(blow_fmu: Path) -> None:
    ours = _failure(blow_fmu, True, _blow_up_advance)
    ref = _failure(blow_fmu, False, _blow_up)
    assert type(ours) is type(ref) and str(ours) == str(ref)


# --------------------------------------------------------------------------- closed form, carry and restart

def _closed_form(x0: float, k: float, dt: float, u: float = 50.0) -> float:
    a = 1.0 / TAU + k
    xs = (u / TAU) / a
    return xs + (x0 - xs) * math.exp(-a * dt)


@pytest.mark.parametrize("restart", [False, True])
def test_parameter_set_mid_run_follows_the_closed_form(first_order_fmu: Path, restart: bool) -> None:
    # dx/dt = (u - x)/TAU - k x, k stepped at 100 s and 200 s: x(t) by hand, segment by segment
    with FMUModel(first_order_fmu, tolerance=1e-9) as model:
        st = model.stepper(start_time=0.0, parameters={"k": K_TWIN}, carry=True, native=True)
        assert isinstance(st, NativeStepper)
        x, t = 38.0, 0.0
        for k_next in (0.0035, 0.004, None):
            k_now = float(st.get(["k"])[0])
            st.step(t + 100.0)
            x, t = _closed_form(x, k_now, 100.0), t + 100.0
            assert st.time == t
            assert float(st.get(["y"])[0]) == pytest.approx(x, rel=1e-7)
            assert st._solver.internal_time() == t  # CVODE stopped exactly at the communication point
            if k_next is not None:
                st.set({"k": k_next}, restart=restart)
        assert (st.carried, st.restarts) == ((0, 2) if restart else (2, 0))


def test_inputs_table_input_override_and_state_overwrite(first_order_fmu: Path) -> None:
    # u ramps 50 -> 60 over 0..100 s (the table, interpolated in C), then u is set to 60.001 at 150 s (carried: the
    # table no longer drives it); at 200 s the state is overwritten with 40 (the solver restarts from it):
    # the Python path step for step, and the closed form over the last 100 s
    times = np.array([0.0, 100.0, 200.0])
    inputs = pd.DataFrame({"time": times, "u": [50.0, 60.0, 60.0]})
    out, counts = {}, {}
    for use_native in (True, False):
        with FMUModel(first_order_fmu, tolerance=1e-9) as model:
            st = model.stepper(inputs=inputs, native=use_native, carry=True)
            ys = []
            for t in np.arange(5.0, 200.1, 5.0):
                if t == 155.0:
                    st.set({"u": 60.001}, restart=False)  # a small change: carried
                st.step(float(t))
                ys.append(float(st.get(["y"])[0]))
            st.set_continuous_states([40.0])
            assert st.get_continuous_states().tolist() == [40.0]
            st.step(300.0)
            ys.append(float(st.get(["y"])[0]))
            out[use_native], counts[use_native] = np.array(ys), (st.restarts, st.carried)
    assert counts[True] == counts[False] == (0, 1)
    assert out[True][-1] == pytest.approx(_closed_form(40.0, K_TWIN, 100.0, u=60.001), rel=1e-7)
    assert np.allclose(out[True], out[False], rtol=1e-7, atol=0.0)


def test_extended_inputs_table(first_order_fmu: Path) -> None:
    # the online mode: the run goes on over a longer table whose first rows are the current one; with u held at
    # 60 after 100 s the state follows the closed form from its value at 100 s, on both paths alike
    t = np.arange(0.0, 301.0, 10.0)
    full = pd.DataFrame({"time": t, "u": np.where(t <= 100.0, 50.0 + 0.1 * t, 60.0)})
    out = {}
    for use_native in (True, False):
        with FMUModel(first_order_fmu, tolerance=1e-9) as model:
            st = model.stepper(inputs=full[full.time <= 100.0], native=use_native, carry=True)
            st.step(100.0)
            x100 = float(st.get(["y"])[0])
            st.extend_inputs(full)
            st.step(300.0)
            out[use_native] = (x100, float(st.get(["y"])[0]))
    x100, x300 = out[True]
    assert x300 == pytest.approx(_closed_form(x100, K_TWIN, 200.0, u=60.0), rel=1e-7)
    assert out[True] == pytest.approx(out[False], rel=1e-9)


# --------------------------------------------------------------------------- failures: same text as the Python path

@pytest.fixture(scope="module")
def blow_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """dx/dt = p x^2, x(0) = 1: with p = 1 from t = 0.5 s, x = 1/(1.5 - t) blows up at t = 1.5 s."""
    return build_casadi_fmu(tmp_path_factory.mktemp("blow"), "blow", variables=[
        ("p", ("parameter", "tunable"), {"start": 0.0}),
        ("x", ("local", "continuous"), {"start": 1.0, "initial": "exact"}),
        ("y", ("output",), {}),
    ], equations=[("der(x)", "p * x * x"), ("y", "x")])


def _failure(fmu: Path, use_native: bool, action) -> SimulationError:
    with FMUModel(fmu) as model:
        st = model.stepper(carry=True, native=use_native)
        with pytest.raises(SimulationError) as exc:
            action(st)
    return exc.value


def _blow_up(st) -> None:
    st.step(0.5)
    st.set({"p": 1.0}, restart=False)
    for t in np.arange(0.6, 3.0, 0.1):
        st.step(float(t))


def _nan_state(st) -> None:
    st.step(0.5)
    st.set_continuous_states([math.nan])
    st.step(1.0)


@pytest.mark.parametrize("action", [_blow_up, _nan_state], ids=["blow-up", "nan-state"])
def test_failures_read_as_on_the_python_path(blow_fmu: Path, action) -> None:
    ours = _failure(blow_fmu, True, action)
    ref = _failure(blow_fmu, False, action)
    assert type(ours) is type(ref)
    assert str(ours) == str(ref)
    assert "blow.fmu" in str(ours)
    if action is _blow_up:
        assert str(ours).startswith("solver failed in blow.fmu between t = 1.4 s and t = 1.5 s: ")


RAMP = """
model Ramp "x = t"
  Real x(start = 0, fixed = true);
equation
  der(x) = 1;
  assert(x < 2, "x too large");
end Ramp;
"""


@pytest.mark.compile
def test_failing_assert_is_the_same_assertion_failed(tmp_path: Path) -> None:
    from trackingbox.compiler import compile_model

    src = tmp_path / "Ramp.mo"
    src.write_text(RAMP)
    fmu = compile_model(src, "Ramp", backend="embedded", output=tmp_path / "Ramp.fmu").fmu

    def run(st) -> None:
        for t in np.arange(0.01, 3.0, 0.01):
            st.step(float(t))

    ours, ref = _failure(fmu, True, run), _failure(fmu, False, run)
    assert isinstance(ours, AssertionFailed) and isinstance(ref, AssertionFailed)
    assert (ours.message, ours.time, str(ours)) == (ref.message, ref.time, str(ref))
    assert ours.message == "x too large" and 2.0 <= ours.time <= 2.01 + 1e-9


# --------------------------------------------------------------------------- fallback

def test_fallback_reasons(monkeypatch, tmp_path: Path, caplog) -> None:
    from _fixtures_fmu import cs3_fmu, me2_fmu, me3_fmu

    cases = {me2_fmu(): "is FMI 2.0; the native stepper drives FMI 3 only", cs3_fmu(): "runs as co-simulation"}
    for fmu, reason in cases.items():
        with FMUModel(fmu) as model, caplog.at_level(logging.DEBUG, logger="trackingbox.fmu"):
            caplog.clear()
            assert not isinstance(model.stepper(), NativeStepper)
            assert reason in model.native_reason
            if model.interface == "ModelExchange":
                assert any(reason in r.getMessage() for r in caplog.records)
            with pytest.raises(FMUError, match="no native stepper for .*" + reason.split(";")[0]):
                model.stepper(native=True)
    with FMUModel(me3_fmu()) as model:
        assert isinstance(model.stepper(), NativeStepper) and model.native_reason is None
        assert type(model.stepper(native=False)) is ModelExchangeStepper
        monkeypatch.setenv("TRACKINGBOX_NATIVE", "0")
        assert type(model.stepper()) is ModelExchangeStepper
        assert model.native_reason == "TRACKINGBOX_NATIVE=0"
        monkeypatch.delenv("TRACKINGBOX_NATIVE")
        # no compiler and nothing built yet (a fresh cache): the Python path, saying why
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
        monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
        assert type(model.stepper()) is ModelExchangeStepper
        assert "no C compiler" in model.native_reason and "no-such-cc" in model.native_reason
        with pytest.raises(FMUError, match="no C compiler"):
            model.stepper(native=True)


# --------------------------------------------------------------------------- a tracking run

@pytest.mark.compile
def test_track_on_the_heat_exchanger_gives_the_python_paths_result(fmu_cache, tmp_path: Path,
                                                                  monkeypatch) -> None:
    from trackingbox.benches import make_bench
    from trackingbox.spec import PairSpec, load_spec, write_pairs
    from trackingbox.tracking.runtime import track

    case = make_bench("heat-exchanger", tmp_path / "case", seed=0, hours=1.0,
                      plant_fmu=fmu_cache("TrackingBox.Benches.HeatExchanger.Plant"),
                      twin_fmu=fmu_cache("TrackingBox.Benches.HeatExchanger.Twin"))
    spec = write_pairs(case.spec, [PairSpec("TI-102", "hx.kht", gain=-0.0237, time_constant=64.0, lambda_=1.0)])
    ours = track(spec, out_dir=tmp_path / "native", checkpoint_every=10**9)
    monkeypatch.setenv("TRACKINGBOX_NATIVE", "0")
    ref = track(spec, out_dir=tmp_path / "python", checkpoint_every=10**9)
    a, b = pd.read_csv(ours.csv), pd.read_csv(ref.csv)
    assert len(a) == len(b) == 361
    assert (ours.restarts, ours.carried) == (ref.restarts, ref.carried) and ours.carried > 100
    spec = load_spec(spec.path)
    for tag in spec.outputs:
        m = a[f"measured:{tag}"]
        span = float(m.quantile(0.99) - m.quantile(0.01))
        for col in (f"tracked:{tag}", f"untracked:{tag}"):
            assert float(np.abs(a[col] - b[col]).max()) <= 1e-6 * span, col
        va, vb = ours.variables[tag], ref.variables[tag]
        assert va.samples == vb.samples
        for field in ("nrmse_tracked", "nrmse_untracked"):
            assert getattr(va, field) == pytest.approx(getattr(vb, field), rel=1e-6, abs=1e-9), (tag, field)
    par = spec.parameter("hx.kht")
    assert float(np.abs(a["parameter:hx.kht"] - b["parameter:hx.kht"]).max()) <= 1e-6 * (par.max - par.min)
    for name, pa in ours.parameters.items():
        pb = ref.parameters[name]
        for field in ("final", "min", "max"):
            assert abs(getattr(pa, field) - getattr(pb, field)) <= 1e-6 * (par.max - par.min), (name, field)
    assert (a["mode:TI-102"] == b["mode:TI-102"]).all()


# --------------------------------------------------------------------------- the Jacobian kept across a restart

def _schedule(fmu: Path, base: dict, inputs: pd.DataFrame | None, p: str, *, keep: bool, restart: bool,
              native_: bool = True, tolerance: float = RTOL):
    """1800 s in 10 s steps, the parameter *p* moved by 1 % every 30 s (restarted or carried), keeping
    CVODE's Jacobian across the restarts or not: (rows of outputs and states, (reused, computed), RHS evaluations)."""
    with FMUModel(fmu, tolerance=tolerance) as model:
        st = model.stepper(parameters=base, inputs=inputs, carry=True, native=native_, keep_jacobian=keep)
        names = model.info.outputs + st.state_names
        read = st.reader(names)
        rows = [read()]
        value = float(base.get(p, st.get([p])[0]))
        r0 = native.rhs_evaluations()
        for k, t in enumerate(np.arange(10.0, 1801.0, 10.0)):
            if k % 3 == 2:
                value *= 1.01
                st.set({p: value}, restart=restart)
            st.step(float(t))
            rows.append(read())
        assert (st.restarts, st.carried) == ((60, 0) if restart else (0, 60))
        jac = st.jacobians() if native_ else (0, 0)
        return np.array(rows), jac, native.rhs_evaluations() - r0


@pytest.mark.compile
def test_the_kept_jacobian_is_cvodes_own_difference_quotient(bench_cases) -> None:
    # without restarts nothing is reused: every Jacobian is CVODE's difference quotient, evaluated by our
    # function as CVODE evaluates it itself, so the run is the run without the function, bit for bit
    fmu, base, inputs, tunable = bench_cases("heat-production")
    ours, (reused, computed), _ = _schedule(fmu, base, inputs, tunable[0], keep=True, restart=False)
    ref, _, _ = _schedule(fmu, base, inputs, tunable[0], keep=False, restart=False)
    assert reused == 0 and computed > 0
    assert np.array_equal(ours, ref)


@pytest.mark.compile
def test_restarts_keeping_the_jacobian_are_as_accurate_and_cheaper(bench_cases) -> None:
    # with a restart every 30 s the first step after each takes the kept Jacobian: the Newton iterates
    # change, not the error test. Against the Python path at rtol 1e-10 (fmpy's CVodeSolver, a new Jacobian
    # at every restart), in units of each variable's magnitude plus range, the run keeping the Jacobian is
    # as accurate as the run evaluating a new one (measured: 3.73e-5 and 3.72e-5 of the worst variable's
    # scale), and its restarts cost fewer FMU derivative calls (3509 against 5246)
    fmu, base, inputs, tunable = bench_cases("heat-production")
    kept, (reused, _), rhs_kept = _schedule(fmu, base, inputs, tunable[0], keep=True, restart=True)
    fresh, (reused_fresh, _), rhs_fresh = _schedule(fmu, base, inputs, tunable[0], keep=False, restart=True)
    ref, _, _ = _schedule(fmu, base, inputs, tunable[0], keep=False, restart=True, native_=False, tolerance=1e-10)
    assert reused == 60 and reused_fresh == 0
    assert rhs_kept < rhs_fresh
    scale = np.abs(ref).max(axis=0) + (ref.max(axis=0) - ref.min(axis=0))
    scale = np.where(scale > 0.0, scale, 1.0)
    err_kept = float((np.abs(kept - ref).max(axis=0) / scale).max())
    err_fresh = float((np.abs(fresh - ref).max(axis=0) / scale).max())
    assert err_kept <= 1.5 * err_fresh


def test_restarts_keeping_the_jacobian_follow_the_closed_form(first_order_fmu: Path) -> None:
    # k stepped every 100 s with a restart at each change: x(t) by hand, segment by segment
    with FMUModel(first_order_fmu, tolerance=1e-9) as model:
        st = model.stepper(start_time=0.0, parameters={"k": K_TWIN}, native=True, keep_jacobian=True)
        x, t, k = 38.0, 0.0, K_TWIN
        for j in range(6):
            st.step(t + 100.0)
            x, t = _closed_form(x, k, 100.0), t + 100.0
            assert float(st.get(["y"])[0]) == pytest.approx(x, rel=1e-7)
            k = K_TWIN * (1.0 + 0.1 * (j + 1))
            st.set({"k": k})
        assert st.restarts == 6
        assert st.jacobians()[0] == 5  # every restart whose first step came reused the last Jacobian
        # before a large change the kept one is forgotten: that restart's first step evaluates a new one
        st.forget_jacobian()
        computed = st.jacobians()[1]
        st.step(t + 100.0)
        x = _closed_form(x, k, 100.0)
        assert float(st.get(["y"])[0]) == pytest.approx(x, rel=1e-7)
        reused, computed_after = st.jacobians()
        assert reused == 5 and computed_after > computed
