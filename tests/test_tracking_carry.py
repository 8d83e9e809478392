"""Carrying the integrator across small parameter changes (issue 12, item 2).

Independent expectations: the closed-form solution of the first-order twin
``dx/dt = (u - x)/tau - k·x`` with ``k`` piecewise constant; on the heat
exchanger bench, the restart path (the integrator re-initialised after every
change), which the carried run must reproduce within 1e-4 of each tag's range;
on the heat-production bench, a restart-path run at a tolerance of 1e-10, which
the restart path (and, once carrying is accurate there, the carried run) at 1e-8
must reproduce within 1e-4 of each tag's and tracked parameter's range.
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


@pytest.mark.compile
def test_carried_tracking_matches_the_restart_path_on_the_heat_exchanger(fmu_cache, tmp_path: Path) -> None:
    # the heat exchanger bench, 2 h, with the pair `trackingbox pair` writes for it; sub-steps as
    # chosen automatically (4 on this bench): the carried run against the restart path. Both at a
    # solver tolerance of 1e-8: at the default 1e-6 the restart path itself is 1.2e-3 of TI-102's
    # range away from a 1e-9 reference (the carried run 6.4e-4, measured), so the comparison would
    # measure the solver's tolerance, not the carrying; at 1e-8 both are within 3.1e-5 of it
    from trackingbox.benches import make_bench

    case = make_bench("heat-exchanger", tmp_path / "case", seed=0, hours=2.0,
                      plant_fmu=fmu_cache("TrackingBox.Benches.HeatExchanger.Plant"),
                      twin_fmu=fmu_cache("TrackingBox.Benches.HeatExchanger.Twin"))
    spec = write_pairs(case.spec, [PairSpec("TI-102", "hx.kht", gain=-0.0237, time_constant=64.0, lambda_=1.0)])
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


@pytest.mark.compile
@pytest.mark.xfail(strict=True, reason=(
    "carrying CVODE across the tracked parameters' changes (the jump in the right-hand side integrated "
    "with the step size and BDF history from before it) is measured 2.3e-3 of FI-200's range from the "
    "reference at 1e-8 (2.1e-3 with the Jacobian kept across its restarts; the restart path 1.7e-5), 7.6e-3 at 1e-6 (the restart path 8.5e-4): on this bench "
    "the carried run is the less accurate; carrying even the large jumps (carry=1e9) is 2.2e-3 at 1e-8, "
    "so the bound tells them apart"))
def test_carried_run_is_within_1e4_of_the_reference_on_heat_production(heat_production_reference,
                                                                        tmp_path: Path) -> None:
    spec, spans, reference = heat_production_reference
    run = track(spec, out_dir=tmp_path / "carried", untracked=False, checkpoint_every=10**9, tolerance=TOLERANCE)
    assert run.carried > 2000
    worst, col = _worst(pd.read_csv(run.csv), reference, spans)
    assert worst <= WITHIN, (col, worst)


def test_track_help_states_the_runtime_default_carry() -> None:
    # `trackingbox track --help` writes the default carry as a literal (importing the runtime would
    # slow every command's start): it must be the runtime's CARRY_FRACTION
    from trackingbox.cli import build_parser

    parser = build_parser()
    track_parser = next(a for a in parser._subparsers._group_actions if a.dest == "command").choices["track"]
    [carry] = [a for a in track_parser._actions if "--carry" in a.option_strings]
    assert f"(default {runtime.CARRY_FRACTION:g})" in carry.help
