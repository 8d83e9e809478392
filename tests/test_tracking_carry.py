"""Carrying the integrator across small parameter changes (issue 12, item 2).

Independent expectations: the closed-form solution of the first-order twin
``dx/dt = (u - x)/tau - k·x`` with ``k`` piecewise constant; on the heat
exchanger bench, the restart path (the integrator re-initialised after every
change), which the carried run must reproduce within 1e-4 of each tag's range;
on the heat-production bench, a restart-path run at a tolerance of 1e-10, which
the restart path at 1e-8 must reproduce within 1e-4 of each tag's and tracked parameter's range.

Tracking's accuracy criterion, with the carried integrator the default on every bench (the
decision of issue 32): at the default tolerance the carried run is within a tenth of each
tag's measured noise (sigma) of the exact trajectory, and each tracked parameter within 1 % of its
bound range. Sigma is measured on the tag's own measurements (second differences: white noise
of sigma gives differences of standard deviation sigma*sqrt(6); a signal that moves slowly over
three samples adds little), the way a modeller would on plant data. The exact trajectory is the
restart path at a tolerance of 1e-10 (CVODE's own Jacobian after every restart), not the restart
path at the default tolerance: on the heat exchanger that one is itself 0.092 sigma of TI-102 from
the exact trajectory, where the carried run is 0.028 (measured, ``scripts/bench_carry --accuracy``),
so a comparison with it would measure its own solver error.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_tracking import K_TWIN, TAU
from trackingbox.fmu import FMUModel
from trackingbox.spec import PairSpec, load_spec, write_pairs
from trackingbox.tracking import runtime, twin
from trackingbox.tracking.runtime import track


def _closed_form(x0: float, k: float, dt: float, u: float = 50.0) -> float:
    a = 1.0 / TAU + k
    xs = (u / TAU) / a
    return xs + (x0 - xs) * math.exp(-a * dt)


@pytest.mark.parametrize("carry", [True, False])
def test_carried_changes_follow_the_closed_form(first_order_fmu: Path, carry: bool) -> None:
    # k steps 0.003 -> 0.0035 -> 0.004 at 100 s and 200 s; the exact x(300 s) by hand, segment by segment
    with FMUModel(first_order_fmu, tolerance=1e-9) as model:
        st = model.stepper(start_time=0.0, parameters={"k": K_TWIN}, carry=carry)
        x, t = 38.0, 0.0
        for k_next in (0.0035, 0.004, None):
            k_now = float(st.get(["k"])[0])
            st.step(t + 100.0)
            x, t = _closed_form(x, k_now, 100.0), t + 100.0
            assert st.time == t
            assert float(st.get(["y"])[0]) == pytest.approx(x, rel=1e-7)
            if carry:  # CVODE stopped exactly at the communication point (its stop time)
                assert st._solver.internal_time() == t
            if k_next is not None:
                st.set({"k": k_next}, restart=False)
        # without carry=True the stepper cannot carry: CVODE stepped past t and interpolated back
        assert (st.carried, st.restarts) == ((2, 0) if carry else (0, 2))
        st.set({"k": 0.005})  # the default is still the restart path
        assert st.restarts == (1 if carry else 3)


def noise_sigma(measured: pd.Series) -> float:
    """The measurement noise of a tag, from its second differences: std(d2 y)/sqrt(6) (white noise)."""
    d2 = np.diff(measured.to_numpy(float), 2)
    return float(np.std(d2[np.isfinite(d2)]) / math.sqrt(6.0))


def criterion(carried: pd.DataFrame, restarted: pd.DataFrame, spec) -> tuple[dict[str, float], dict[str, float]]:
    """Tracking's accuracy criterion: ``{tag: max |carried - restarted| / sigma}`` over the
    run (sigma: :func:`noise_sigma` of the tag's measurements), ``{parameter: max |...| / bound range}``;
    *restarted* is the exact trajectory (:func:`exact_run`)."""
    assert len(carried) == len(restarted)
    tags = {tag: float(np.abs(carried[f"tracked:{tag}"] - restarted[f"tracked:{tag}"]).max())
            / noise_sigma(carried[f"measured:{tag}"]) for tag in spec.outputs}
    parameters = {}
    for p in spec.pairs:
        par = spec.parameter(p.parameter)
        parameters[p.parameter] = float(np.abs(carried[f"parameter:{p.parameter}"]
                                               - restarted[f"parameter:{p.parameter}"]).max()) / (par.max - par.min)
    return tags, parameters


def test_noise_sigma_reads_white_noise_under_a_slow_signal() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 7200.0, 10.0)
    # a 2 K swing over an hour: second differences of A w^2 dt^2 = 6.1e-4 K at most, 1.8e-4 K as a sigma
    signal = 350.0 + 2.0 * np.sin(2 * np.pi * t / 3600.0)
    assert noise_sigma(pd.Series(signal + rng.normal(0.0, 0.1, t.size))) == pytest.approx(0.1, rel=0.1)
    assert noise_sigma(pd.Series(signal)) < 0.002


#: Solver tolerance of the exact trajectory (the restart path) the criterion measures against
EXACT_TOLERANCE = 1e-10


def exact_run(spec, out_dir: Path, **kw):
    """The restart path at :data:`EXACT_TOLERANCE`, CVODE's own Jacobian after every restart."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(twin, "KEEP_JACOBIAN", False)
        return track(spec, out_dir=out_dir, checkpoint_every=10**9, carry=0.0, tolerance=EXACT_TOLERANCE, **kw)


@pytest.fixture(scope="module")
def heat_exchanger_case(fmu_cache, tmp_path_factory: pytest.TempPathFactory):
    """The heat exchanger bench, 2 h, seed 0, with the pair `trackingbox pair` writes for it; its spec."""
    from trackingbox.benches import make_bench

    case = make_bench("heat-exchanger", tmp_path_factory.mktemp("hx-carry") / "case", seed=0, hours=2.0,
                      plant_fmu=fmu_cache("TrackingBox.Benches.HeatExchanger.Plant"),
                      twin_fmu=fmu_cache("TrackingBox.Benches.HeatExchanger.Twin"))
    return write_pairs(case.spec, [PairSpec("TI-102", "hx.kht", gain=-0.0237, time_constant=64.0, lambda_=1.0)])


@pytest.mark.compile
def test_carried_run_meets_the_accuracy_criterion_on_the_heat_exchanger(heat_exchanger_case,
                                                                          tmp_path: Path) -> None:
    # the carried run at the default tolerance, as every bench runs, against the exact trajectory.
    # Measured: TI-102 0.028 sigma, TI-202 0.038 (sigma 0.097 and 0.102 K, the bench's 0.1 K), hx.kht
    # 1.6e-4 of its bound range. Against the restart path at the default tolerance it would be TI-102
    # 0.103 sigma: that path's own solver error (0.092 sigma from the exact trajectory)
    spec = heat_exchanger_case
    carried = track(spec, out_dir=tmp_path / "carried", checkpoint_every=10**9)
    exact = exact_run(spec, tmp_path / "exact")
    assert carried.carried > 2000 and exact.carried == 0
    tags, parameters = criterion(pd.read_csv(carried.csv), pd.read_csv(exact.csv), load_spec(spec.path))
    assert set(tags) == {"TI-102", "TI-202"} and set(parameters) == {"hx.kht"}
    assert {t: r for t, r in tags.items() if r > 0.1} == {}, tags
    assert {p: r for p, r in parameters.items() if r > 0.01} == {}, parameters


@pytest.mark.compile
def test_carried_tracking_matches_the_restart_path_on_the_heat_exchanger(heat_exchanger_case,
                                                                           tmp_path: Path) -> None:
    # the heat exchanger bench, 2 h, with the pair `trackingbox pair` writes for it; sub-steps as
    # chosen automatically (4 on this bench): the carried run against the restart path. Both at a
    # solver tolerance of 1e-8: at the default 1e-6 the restart path itself is 1.2e-3 of TI-102's
    # range away from a 1e-9 reference (the carried run 6.4e-4, measured), so the comparison would
    # measure the solver's tolerance, not the carrying; at 1e-8 both are within 3.1e-5 of it
    spec = heat_exchanger_case
    carried = track(spec, out_dir=tmp_path / "carried", checkpoint_every=10**9, tolerance=1e-8)
    restarted = track(spec, out_dir=tmp_path / "restarted", checkpoint_every=10**9, carry=0.0, tolerance=1e-8)
    a, b = pd.read_csv(carried.csv), pd.read_csv(restarted.csv)
    assert len(a) == len(b) == 721
    # the restart path re-initialises at every change; the carried run only at the end of the start-up hold
    assert restarted.carried == 0 and restarted.restarts > 2000
    assert carried.carried > 2000 and carried.restarts <= 5
    spec = load_spec(spec.path)
    for tag in spec.outputs:
        m = a[f"measured:{tag}"]
        span = float(m.quantile(0.99) - m.quantile(0.01))
        diff = float(np.abs(a[f"tracked:{tag}"] - b[f"tracked:{tag}"]).max())
        assert diff <= 1e-4 * span, (tag, diff / span)
    par = spec.parameter("hx.kht")
    diff = float(np.abs(a["parameter:hx.kht"] - b["parameter:hx.kht"]).max())
    assert diff <= 1e-4 * (par.max - par.min), diff / (par.max - par.min)
    assert (a["mode:TI-102"] == b["mode:TI-102"]).all()


def test_extended_inputs_continue_the_carried_run_exactly(first_order_fmu: Path) -> None:
    # the online mode's case: the input table grows while the run goes on. A carried stepper stops at
    # every communication point, so going on with the longer table gives the run over the whole table,
    # bit for bit; a newer run of the model releases the finished one's table
    t = np.arange(0.0, 400.0 + 1e-9, 10.0)
    table = pd.DataFrame({"time": t, "u": 50.0 + 10.0 * (t >= 150.0) + 0.05 * t})
    ys = []
    with FMUModel(first_order_fmu) as model:
        for parts in (1, 2):
            st = model.stepper(start_time=0.0, parameters={"k": K_TWIN}, inputs=table[: 21 if parts == 2 else None],
                               carry=True)
            y = []
            for j, tk in enumerate(t[1:], start=1):
                if parts == 2 and j == 21:
                    st.extend_inputs(table)
                st.step(tk)
                st.set({"k": K_TWIN * (1.0 + 0.001 * j)}, restart=False)
                y.append(float(st.get(["y"])[0]))
            ys.append(y)
            first = st
        assert ys[0] == ys[1]
        model.stepper(start_time=0.0, parameters={"k": K_TWIN})
        assert first._in_table is None


# The heat-production bench, 2 h, seed 0, with the eight pairs `trackingbox pair` (defaults: closed-loop
# step tests) writes for it: (tag, parameter, gain, time constant). Sub-steps as chosen automatically.
HEAT_PRODUCTION_PAIRS = (
    ("TI-301", "HEX300.kht", -0.010779, 81.84),
    ("TI-310", "HU300.kht", -0.021426, 148.8),
    ("PI-100", "Pipe100.k", 616297.4, 175.0),
    ("PI-200", "Pipe200.k", 616297.9, 88.15),
    ("PI-300", "Pipe201.k", 616298.2, 12.32),
    ("SI-100", "PU100.uRise", -5.2957e-06, 1175.1),
    ("SI-200", "PU200.uRise", -5.6662e-06, 114.16),
    ("ZI-400", "Pipe101.k", 13.6387, 1545.7),
)
#: Solver tolerance of the compared runs, and of the reference (the restart path): 1e-10 is within 9e-7 of
#: each range of the restart path at 1e-12 on this case (measured), so it stands for the exact trajectory
TOLERANCE, REFERENCE_TOLERANCE = 1e-8, 1e-10
#: Issue 12's yardstick, in units of each tag's range (1st to 99th percentile of its measurements) and of
#: each tracked parameter's bound range
WITHIN = 1e-4


@pytest.fixture(scope="module")
def heat_production_reference(fmu_cache, tmp_path_factory: pytest.TempPathFactory):
    """The case's spec, its ranges by CSV column, and the reference run's table (restart path, 1e-10)."""
    from trackingbox.benches import make_bench

    root = tmp_path_factory.mktemp("hp-carry")
    case = make_bench("heat-production", root / "case", seed=0, hours=2.0,
                      plant_fmu=fmu_cache("TrackingBox.Benches.HeatProduction.Plant"),
                      twin_fmu=fmu_cache("TrackingBox.Benches.HeatProduction.Twin"))
    spec = write_pairs(case.spec, [PairSpec(v, p, gain=g, time_constant=t, lambda_=1.0)
                                   for v, p, g, t in HEAT_PRODUCTION_PAIRS])
    with pytest.MonkeyPatch.context() as mp:  # the reference: CVODE's own Jacobian after every restart
        mp.setattr(twin, "KEEP_JACOBIAN", False)
        ref = track(spec, out_dir=root / "reference", untracked=False, checkpoint_every=10**9, carry=0.0,
                    tolerance=REFERENCE_TOLERANCE)
    c = pd.read_csv(ref.csv)
    spec = load_spec(spec.path)
    spans = {}
    for tag in spec.outputs:
        m = c[f"measured:{tag}"]
        spans[f"tracked:{tag}"] = float(m.quantile(0.99) - m.quantile(0.01))
    for _, name, *_ in HEAT_PRODUCTION_PAIRS:
        par = spec.parameter(name)
        spans[f"parameter:{name}"] = par.max - par.min
    return spec, spans, c


def _worst(run: pd.DataFrame, reference: pd.DataFrame, spans: dict[str, float]) -> tuple[float, str]:
    assert len(run) == len(reference) == 721
    return max((float(np.abs(run[col] - reference[col]).max()) / span, col) for col, span in spans.items())


@pytest.mark.compile
def test_restart_path_is_within_1e4_of_the_reference_on_heat_production(heat_production_reference,
                                                                          tmp_path: Path) -> None:
    # the restart path as track() runs it: its twin keeps CVODE's Jacobian across the restarts (the
    # reference does not; measured the same 1.65e-5 either way)
    # measured at 1e-8: at most 1.7e-5 of a range (FI-200), every tag and tracked parameter; at the
    # default 1e-6 it is 8.5e-4 (FI-200): the 1e-4 needs the tighter tolerance on this closed loop.
    # A run that carries every change, the large jumps too (carry=1e9), is 2.2e-3 away at 1e-8: it fails
    spec, spans, reference = heat_production_reference
    run = track(spec, out_dir=tmp_path / "restarted", untracked=False, checkpoint_every=10**9, carry=0.0,
                tolerance=TOLERANCE)
    assert run.carried == 0 and run.restarts > 3000
    worst, col = _worst(pd.read_csv(run.csv), reference, spans)
    assert worst <= WITHIN, (col, worst)


@pytest.fixture(scope="module")
def heat_production_runs(heat_production_reference, tmp_path_factory: pytest.TempPathFactory):
    """The carried run at the default tolerance against the exact trajectory (the reference: the
    restart path at 1e-10, :data:`REFERENCE_TOLERANCE` = :data:`EXACT_TOLERANCE`); the criterion's figures."""
    spec, _, reference = heat_production_reference
    assert REFERENCE_TOLERANCE == EXACT_TOLERANCE
    root = tmp_path_factory.mktemp("hp-criterion")
    carried = track(spec, out_dir=root / "carried", untracked=False, checkpoint_every=10**9)
    assert carried.carried > 2000
    return criterion(pd.read_csv(carried.csv), reference, spec)


@pytest.mark.compile
def test_carried_parameters_are_within_1_percent_of_the_exact_trajectory_on_heat_production(
        heat_production_runs) -> None:
    # measured against the exact trajectory: 1.9e-3 of the bound range at most (PU200.uRise), HEX300.kht
    # and HU300.kht 8.1e-4 and 1.0e-3
    _, parameters = heat_production_runs
    assert set(parameters) == {name for _, name, *_ in HEAT_PRODUCTION_PAIRS}
    assert {p: r for p, r in parameters.items() if r > 0.01} == {}, parameters


@pytest.mark.compile
@pytest.mark.xfail(strict=True, reason=(
    "measured at the default tolerance (2 h, seed 0) against the exact trajectory: FI-200 is 0.114 sigma "
    "(sigma 3.2e-4 kg/s), and the controller outputs, which the DCS knows without noise (their second "
    "differences give sigma 4.5e-6 SI-100, 2.6e-4 SI-200, 8.8e-6 ZI-400), 4.06, 0.315 and 4.37 sigma; "
    "every other tag 0.045 sigma at most. It is the carrying: the restart path at the same tolerance is "
    "0.0115, 0.61, 0.029 and 0.45 sigma from it, and a carry fraction of 0.005 instead of 0.02 (514 of 3239 "
    "changes carried, not 2510) gives FI-200 0.032 (scripts/bench_carry --accuracy --carry). At 1e-8 "
    "FI-200 is 0.028 sigma but SI-100 and ZI-400 still 0.80 and 0.83: on this bench the carried run does "
    "not meet a tenth of the noise, and on noise-free tags the default tolerance alone does not"))
def test_carried_tags_are_within_a_tenth_of_their_noise_of_the_exact_trajectory_on_heat_production(
        heat_production_runs) -> None:
    tags, _ = heat_production_runs
    assert {t: r for t, r in tags.items() if r > 0.1} == {}, tags


def test_track_help_states_the_runtime_default_carry() -> None:
    # `trackingbox track --help` writes the default carry as a literal (importing the runtime would
    # slow every command's start): it must be the runtime's CARRY_FRACTION
    from trackingbox.cli import build_parser

    parser = build_parser()
    track_parser = next(a for a in parser._subparsers._group_actions if a.dest == "command").choices["track"]
    [carry] = [a for a in track_parser._actions if "--carry" in a.option_strings]
    assert f"(default {runtime.CARRY_FRACTION:g})" in carry.help
