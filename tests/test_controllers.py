"""Parameter controllers, state compensation and SIMC tuning against hand-computed numbers."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from trackingbox.tracking.controllers import (
    Scaling,
    ScaledPI,
    SlidingMode,
    StateCompensator,
    direction_from_gain,
)
from trackingbox.tracking.tuning import scaled_process_gain, simc_pi, tune_scaled_pi

# Scaling(0, 10, span=2): 1 parameter unit = 10 %, 0.1 variable units = 5 % error.
# te = ts/100: the error memory settles to exp(-100) within a sample, so the
# hand-computed numbers are those of the textbook velocity form
# u(k) = u(k-1) + kp (e(k) - e(k-1)) + kp Ts/Ti e(k).


def _pi(direction: int = 1, p0: float = 5.0, span: float = 2.0) -> ScaledPI:
    return ScaledPI(Scaling(0.0, 10.0, span=span), kp=2.0, ti=40.0, ts=10.0, direction=direction, p0=p0, te=0.1)


def test_scaling_maps_bounds_and_normalises_error() -> None:
    s = Scaling(800.0, 1200.0, span=4.0)
    assert s.to_parameter(0.0) == 800.0
    assert s.to_parameter(100.0) == 1200.0
    assert s.to_percent(910.0) == pytest.approx(27.5)
    assert s.error_percent(51.0, 50.0) == pytest.approx(25.0)


def test_scaling_rejects_bad_bounds() -> None:
    with pytest.raises(ValueError):
        Scaling(1.0, 1.0, span=1.0)
    with pytest.raises(ValueError):
        Scaling(0.0, 1.0, span=0.0)


def test_pi_velocity_form_sequence_by_hand() -> None:
    # kp=2, Ts/Ti=1/4; errors 10 %, 5 %, 0 %:
    # du1 = 2*0 + 0.5*10 = 5 -> 55 %; du2 = 2*(-5) + 0.5*5 = -7.5 -> 47.5 %; du3 = 2*(-5) + 0 = -10 -> 37.5 %
    pi = _pi()
    assert pi.update(1.0, 0.8, hold=True) == 5.0  # start-up hold: the error memory settles on 10 %
    assert pi.update(1.0, 0.8) == pytest.approx(5.5)
    assert pi.update(1.0, 0.9) == pytest.approx(4.75)
    assert pi.update(1.0, 1.0) == pytest.approx(3.75)
    assert pi.mode == "auto"


def test_pi_reverse_acting_mirrors_increments() -> None:
    # negative pair gain: same increments with the opposite sign -> 45 %, 52.5 %, 62.5 %
    pi = _pi(direction=direction_from_gain(-0.004))
    pi.update(1.0, 0.8, hold=True)
    assert [pi.update(1.0, pv) for pv in (0.8, 0.9, 1.0)] == pytest.approx([4.5, 5.25, 6.25])


def test_direction_from_gain() -> None:
    assert direction_from_gain(3.0) == 1
    assert direction_from_gain(-1e-6) == -1
    with pytest.raises(ValueError):
        direction_from_gain(0.0)


def test_pi_clamps_and_leaves_bound_at_once() -> None:
    pi = _pi(p0=9.8)  # 98 %
    pi.update(1.0, 0.8, hold=True)
    assert pi.update(1.0, 0.8) == 10.0  # 98 + 5 -> clamped at 100 %
    assert pi.update(1.0, 0.8) == 10.0  # still pushing: stays at 100 %, nothing stored
    # error flips to -10 %: du = 2*(-20) + 0.5*(-10) = -45 -> 55 % on this very step
    assert pi.update(1.0, 1.2) == pytest.approx(5.5)


def test_pi_clamps_at_lower_bound() -> None:
    pi = _pi(p0=0.1)  # 1 %
    pi.update(1.0, 1.2, hold=True)
    assert pi.update(1.0, 1.2) == 0.0  # du = -5 -> -4 % clamped to 0 %
    assert 0.0 <= pi.value <= 10.0


def test_pi_initial_value_outside_bounds_is_clamped() -> None:
    assert _pi(p0=12.0).value == 10.0


def test_pi_first_sample_without_hold_acts_on_the_whole_error() -> None:
    # the memory starts at 0 (as the block's state): kp*(10 - 0) + Ts/Ti*kp*10 = 25 % -> 75 %
    assert _pi().update(1.0, 0.8) == pytest.approx(7.5)


def test_pi_hold_on_nan_and_bumpless_resume() -> None:
    pi = _pi()
    pi.update(1.0, 0.8, hold=True)
    assert pi.update(1.0, 0.8) == pytest.approx(5.5)  # e = 10 %
    assert pi.update(math.nan, 0.8) == pytest.approx(5.5)  # missing measurement: frozen
    assert pi.mode == "hold"
    assert pi.update(1.0, 0.5, hold=True) == pytest.approx(5.5)  # flagged: frozen, no integration
    assert pi.update(None, None) == pytest.approx(5.5)
    # resume with e = 20 %: history reset, so only the integral acts: du = 0.5*20 = 10 -> 65 %
    # (without the reset the kick would be 2*(20-10) + 10 = 30 -> 85 %)
    assert pi.update(1.0, 0.6) == pytest.approx(6.5)
    assert pi.mode == "auto"


def test_pi_state_round_trip() -> None:
    a, b = _pi(), _pi()
    a.update(1.0, 0.8, hold=True)
    a.update(1.0, 0.8)
    b.load_state_dict(a.state_dict())
    assert a.update(1.0, 0.9) == b.update(1.0, 0.9)


def test_pi_closes_loop_on_first_order_process() -> None:
    # discrete first-order process y(k+1) = a*y(k) + (1-a)*(8 + g*p(k)), g = -0.004, tau = 300 s,
    # Ts = 10 s; the "plant" has p* = 910, so the setpoint is 8 + g*910 and p must settle at 910.
    g, tau, ts = -0.004, 300.0, 10.0
    scaling = Scaling(800.0, 1200.0, span=abs(g) * 400.0)
    gains = tune_scaled_pi(g, tau, scaling, ts=ts)
    pi = ScaledPI(scaling, kp=gains.kp, ti=gains.ti, ts=ts, direction=direction_from_gain(g), p0=1000.0)
    a = math.exp(-ts / tau)
    y, p = 8.0 + g * 1000.0, 1000.0
    sp = 8.0 + g * 910.0
    for _ in range(800):
        p = pi.update(sp, y)
        y = a * y + (1.0 - a) * (8.0 + g * p)
    assert p == pytest.approx(910.0, rel=1e-4)
    assert y == pytest.approx(sp, abs=1e-5)


def test_sliding_mode_sequence_by_hand() -> None:
    sm = SlidingMode(Scaling(0.0, 10.0, span=2.0), eta=0.5, phi=5.0, lam=20.0, ts=10.0, direction=1, p0=5.0)
    # e=10: s = 10 -> sat = 1 -> du = 10*0.5 = 5 -> 55 %
    assert sm.update(1.0, 0.8) == pytest.approx(5.5)
    # e=2: s = 2 + 20*(2-10)/10 = -14 -> sat = -1 -> du = -5 -> 50 %
    assert sm.update(1.0, 0.96) == pytest.approx(5.0)
    # e=2: s = 2 -> sat = 0.4 -> du = 2 -> 52 %
    assert sm.update(1.0, 0.96) == pytest.approx(5.2)
    # a huge error moves the parameter by at most eta*Ts = 5 % per step
    assert sm.update(1000.0, 0.0) == pytest.approx(5.7)


def test_sliding_mode_equals_pi_inside_boundary_layer() -> None:
    scaling = Scaling(0.0, 10.0, span=20.0)  # errors 1 %, 0.5 %, 0 %
    sm = SlidingMode.from_pi(scaling, kp=2.0, ti=40.0, ts=10.0, direction=1, p0=5.0, phi=5.0)
    # PI by hand: du = 0.5, -0.75, -1.0 (% of 10) -> 5.05, 4.975, 4.875
    assert [sm.update(1.0, pv) for pv in (0.8, 0.9, 1.0)] == pytest.approx([5.05, 4.975, 4.875])


def test_sliding_mode_hold_reverse_and_clamp() -> None:
    sm = SlidingMode(Scaling(0.0, 10.0, span=2.0), eta=0.5, phi=5.0, lam=0.0, ts=10.0, direction=-1, p0=0.2)
    assert sm.update(1.0, 0.8) == 0.0  # reverse: 2 % - 5 % -> clamped at 0 %
    assert sm.update(math.nan, 0.8) == 0.0
    assert sm.mode == "hold"
    assert sm.update(1.0, 1.2) == pytest.approx(0.5)  # e = -10 %: +5 %


def test_state_compensator_proportional_by_hand() -> None:
    sc = StateCompensator(5.0, ts=10.0, te=0.1)
    assert sc.update(2.0, 1.8) == pytest.approx(1.0)  # 5 kg/s/m * 0.2 m
    assert sc.update(2.0, 1.9) == pytest.approx(0.5)  # follows K*e
    assert sc.update(2.0, 2.1) == pytest.approx(-0.5)


def test_state_compensator_default_memory_lags_by_exp_minus_ten() -> None:
    # te = ts/10 by default: the first step reaches K*e*(1 - exp(-10)) from zero
    sc = StateCompensator(5.0, ts=10.0)
    assert sc.update(2.0, 1.8) == pytest.approx(1.0 * (1.0 - math.exp(-10.0)), rel=1e-12)


def test_state_compensator_hold_and_resume_to_k_times_e() -> None:
    # a proportional law: held or missing, the correction is frozen; afterwards it is K*e again, with
    # no memory of the hold (re-basing there would keep K*(e_hold - e_release) as a permanent flow)
    sc = StateCompensator(5.0, ts=10.0, te=0.1)
    assert sc.update(2.0, 1.8) == pytest.approx(1.0)
    assert sc.update(2.0, 1.5, hold=True) == pytest.approx(1.0)  # frozen
    assert sc.mode == "hold"
    assert sc.update(2.0, 1.4) == pytest.approx(3.0)  # 5 kg/s/m * 0.6 m
    assert sc.update(math.nan, 1.4) == pytest.approx(3.0)  # missing: frozen
    assert sc.update(2.0, 1.0) == pytest.approx(5.0)  # 5 * 1.0
    assert sc.update(2.0, 1.2) == pytest.approx(4.0)  # 5 * 0.8


def test_state_compensator_missing_first_sample_leaves_no_offset() -> None:
    # a historian export starts without a value: the correction must still be K*e from then on
    for interpolation in ("zoh", "linear"):
        sc = StateCompensator(7.0, ts=10.0, te=1.0, interpolation=interpolation)
        sc.update(math.nan, 1.22)
        for _ in range(5):
            m = sc.update(1.20, 1.22)
        assert m == pytest.approx(7.0 * -0.02, rel=1e-6), interpolation
        for _ in range(5):
            m = sc.update(1.20, 1.20)
        assert m == pytest.approx(0.0, abs=1e-9), interpolation   # level on the plant's: no flow left


def test_state_compensator_holds_level_with_proportional_offset() -> None:
    # twin tank: level integrates (correction - 0.2 kg/s)/(rho*A), a 0.2 kg/s outflow the plant
    # does not have. A proportional correction settles where K*e = 0.2: e = 0.2/50 = 4 mm.
    rho_a, ts = 1000.0, 10.0
    sc = StateCompensator(50.0, ts=ts)
    level, plant = 1.0, 1.0
    for _ in range(600):
        m = sc.update(plant, level)
        level += ts * (m - 0.2) / rho_a
    assert plant - level == pytest.approx(0.004, rel=1e-4)
    assert sc.m == pytest.approx(0.2, rel=1e-6)


def test_state_round_trips() -> None:
    a, b = StateCompensator(5.0, ts=10.0), StateCompensator(5.0, ts=10.0)
    a.update(2.0, 1.8)
    b.load_state_dict(a.state_dict())
    assert a.update(2.0, 1.7) == b.update(2.0, 1.7)


def test_simc_by_hand() -> None:
    # Kc = tau/(K(tc+theta)), Ti = min(tau, 4(tc+theta))
    assert simc_pi(0.5, 100.0, 5.0, tau_c=20.0) == pytest.approx((8.0, 100.0))
    assert simc_pi(-0.5, 1000.0, 0.0, tau_c=10.0) == pytest.approx((200.0, 40.0))
    kc, ti = simc_pi(0.5, 100.0, 5.0)  # tau_c defaults to tau
    assert (kc, ti) == pytest.approx((100.0 / (0.5 * 105.0), 100.0))


def test_scaled_tuning_by_hand() -> None:
    # kht in [800, 1200], variable span 1.6 K: Ks = -0.004*400/1.6 = -1
    scaling = Scaling(800.0, 1200.0, span=1.6)
    assert scaled_process_gain(-0.004, scaling) == pytest.approx(-1.0)
    g = tune_scaled_pi(-0.004, 300.0, scaling, ts=10.0, lam=1.0)
    # theta = Ts/2 = 5, tau_c = 300: Kp = 300/(1*305), Ti = min(300, 1220)
    assert g.kp == pytest.approx(300.0 / 305.0)
    assert g.ti == pytest.approx(300.0)
    # engineering units: Kc = tau/(|K|(tc+theta)) = 300/(0.004*305)
    assert g.kc == pytest.approx(300.0 / (0.004 * 305.0))
    g2 = tune_scaled_pi(-0.004, 300.0, scaling, ts=10.0, lam=0.1)
    # tau_c = 30: Kp = 300/35, Ti = min(300, 140) = 140
    assert (g2.kp, g2.ti) == pytest.approx((300.0 / 35.0, 140.0))


def test_tuning_rejects_zero_gain() -> None:
    with pytest.raises(ValueError):
        simc_pi(0.0, 100.0)
    assert np.isfinite(simc_pi(1e-9, 1.0)[0])


def test_pair_settings_one_rule_for_span_and_gains() -> None:
    from types import SimpleNamespace

    from trackingbox.errors import SpecError
    from trackingbox.tracking.tuning import pair_settings

    pair = SimpleNamespace(variable="TI-102", parameter="hx.kht", gain=-0.004, time_constant=300.0,
                           lambda_=1.0, kp=None, ti=None)
    s = pair_settings(pair, 800.0, 1200.0, ts=10.0)
    # span = |g|*(pmax - pmin) = 1.6; Ks = -1; SIMC with theta = 5 s, tau_c = 300 s
    assert s.scaling.span == pytest.approx(1.6)
    assert (s.kp, s.ti, s.direction) == pytest.approx((300.0 / 305.0, 300.0, -1))
    explicit = SimpleNamespace(**{**vars(pair), "kp": 0.7, "ti": 90.0})
    assert (pair_settings(explicit, 800.0, 1200.0, ts=10.0).kp, 90.0) == (0.7, 90.0)
    with pytest.raises(SpecError, match=r"TI-102 -> hx.kht.*kp = -0.7.*magnitude"):
        pair_settings(SimpleNamespace(**{**vars(pair), "kp": -0.7}), 800.0, 1200.0, ts=10.0)
    with pytest.raises(SpecError, match="span"):
        pair_settings(SimpleNamespace(**{**vars(pair), "gain": 0.0}), 800.0, 1200.0, ts=10.0)


# -- the Python controllers against the compiled Modelica blocks -------------

# The settings of TrackingBox.Blocks.Validation.ParameterControllerInputs
_BLOCK = {"p_min": 800.0, "p_max": 1200.0, "p0": 1000.0, "span": 2.0, "kp": 0.5, "ti": 60.0, "te": 1.0, "k": 5.0}
_TS = 10.0

# u_s - u_m per sample (span 2: 0.02 is 1 %) and the hold input: start-up hold, a large
# positive error that drives the direct controller to 100 % and the reverse one to 0 %,
# a small error whose proportional step pulls both off their bounds while the integral
# pushes back (the rate changes sign within a sample), a hold with a changing error,
# a negative error that saturates both the other way, resumption and a noisy stretch.
_DIFF = ([0.2, 0.4, 0.4] + [2.0] * 6 + [0.1] * 3 + [-0.5, -1.0, -1.5, -1.0] + [-1.5] * 10 + [0.3] * 5
         + list(np.round(np.random.default_rng(8).normal(0.0, 0.3, 20), 4)))
_HOLD = [1.0] * 3 + [0.0] * 9 + [1.0] * 4 + [0.0] * 15 + [1.0 if 40 <= k < 43 else 0.0 for k in range(31, 51)]


def test_python_controllers_match_the_compiled_blocks(fmu_cache) -> None:
    from trackingbox.fmu import FMUModel

    assert len(_DIFF) == len(_HOLD) == 51
    fmu = fmu_cache("TrackingBox.Blocks.Validation.ParameterControllerInputs")
    b = _BLOCK
    scaling = Scaling(b["p_min"], b["p_max"], span=b["span"])
    direct = ScaledPI(scaling, kp=b["kp"], ti=b["ti"], ts=_TS, te=b["te"], direction=1, p0=b["p0"])
    reverse = ScaledPI(scaling, kp=b["kp"], ti=b["ti"], ts=_TS, te=b["te"], direction=-1, p0=b["p0"])
    comp = StateCompensator(b["k"], ts=_TS, te=b["te"])
    py, mo = [], []
    with FMUModel(fmu, tolerance=1e-10) as model:
        run = model.stepper(start_time=0.0)
        for k, (diff, hold) in enumerate(zip(_DIFF, _HOLD)):
            u_s, u_m = 50.0 + diff, 50.0
            run.set({"u_s": u_s, "u_m": u_m, "hold": hold})
            run.step((k + 1) * _TS)
            mo.append(run.get(["yDirect", "yReverse", "m"]))
            py.append([direct.update(u_s, u_m, hold=hold > 0.5), reverse.update(u_s, u_m, hold=hold > 0.5),
                       comp.update(u_s, u_m, hold=hold > 0.5)])
    py_a, mo_a = np.array(py), np.array(mo)
    # the sequence does what it claims: both bounds reached by both controllers, holds freeze
    for j in (0, 1):
        assert py_a[:, j].max() == b["p_max"] and py_a[:, j].min() == b["p_min"]
    assert np.all(py_a[12:16, :] == py_a[11, :])
    tol = 1e-6 * (b["p_max"] - b["p_min"])
    assert np.abs(py_a[:, :2] - mo_a[:, :2]).max() <= tol, np.abs(py_a - mo_a).max(axis=0)
    # the correction: within 1e-6 of its range K*max|diff|
    assert np.abs(py_a[:, 2] - mo_a[:, 2]).max() <= 1e-6 * b["k"] * 2.0


def test_linear_python_controllers_match_the_compiled_blocks_with_interpolated_inputs(fmu_cache) -> None:
    # The same recorded sequence, this time as the compiled box sees a measurement: u_s linear between
    # the samples (the FMU's input table), the hold a flag per sample (set between steps). The
    # controllers with interpolation="linear" return, at the call with sample k, the block's value at t_k.
    from trackingbox.fmu import FMUModel

    fmu = fmu_cache("TrackingBox.Blocks.Validation.ParameterControllerInputs")
    b = _BLOCK
    scaling = Scaling(b["p_min"], b["p_max"], span=b["span"])
    kw = dict(kp=b["kp"], ti=b["ti"], ts=_TS, te=b["te"], p0=b["p0"], interpolation="linear")
    direct, reverse = ScaledPI(scaling, direction=1, **kw), ScaledPI(scaling, direction=-1, **kw)
    comp = StateCompensator(b["k"], ts=_TS, te=b["te"], interpolation="linear")
    grid = _TS * np.arange(len(_DIFF))
    table = pd.DataFrame({"time": grid, "u_s": 50.0 + np.asarray(_DIFF), "u_m": np.full(grid.size, 50.0)})
    py, mo = [], []
    with FMUModel(fmu, tolerance=1e-10) as model:
        run = model.stepper(start_time=0.0, inputs=table)
        for k, (diff, hold) in enumerate(zip(_DIFF, _HOLD)):
            mo.append(run.get(["yDirect", "yReverse", "m"]))
            u_s = 50.0 + diff
            py.append([direct.update(u_s, 50.0, hold=hold > 0.5), reverse.update(u_s, 50.0, hold=hold > 0.5),
                       comp.update(u_s, 50.0, hold=hold > 0.5)])
            if k + 1 < grid.size:
                run.set({"hold": hold})
                run.step(grid[k + 1])
    py_a, mo_a = np.array(py), np.array(mo)
    # both bounds are reached (the ramped error saturates less than the held one, see above)
    assert py_a[:, :2].max() == b["p_max"] and py_a[:, :2].min() == b["p_min"], (py_a[:, 0].max(), py_a[:, 1].min())
    # the linear error differs from the held one: the check is not the zero-order-hold one again
    zoh = ScaledPI(scaling, kp=b["kp"], ti=b["ti"], ts=_TS, te=b["te"], direction=1, p0=b["p0"])
    held = [b["p0"]] + [zoh.update(50.0 + d, 50.0, hold=h > 0.5) for d, h in zip(_DIFF[:-1], _HOLD[:-1])]
    assert np.abs(np.array(held) - py_a[:, 0]).max() > 1e-2 * (b["p_max"] - b["p_min"])
    tol = 1e-6 * (b["p_max"] - b["p_min"])
    assert np.abs(py_a[:, :2] - mo_a[:, :2]).max() <= tol, np.abs(py_a - mo_a).max(axis=0)
    assert np.abs(py_a[:, 2] - mo_a[:, 2]).max() <= 1e-6 * b["k"] * 2.0


@pytest.mark.parametrize("u0, e, mem", [(1.0, 5.0, 40.0), (99.0, -5.0, -40.0), (99.5, 30.0, 35.0), (50.0, 10.0, 0.0)])
def test_exact_step_matches_a_fine_clamped_integration(u0: float, e: float, mem: float) -> None:
    # one sample of du/dt = kp (e/Ti + (e - m)/Te), dm/dt = (e - m)/Te with u clamped to 0..100 by
    # conditional integration, integrated with 200 000 explicit Euler steps. In the first two cases
    # the proportional step runs into a bound and the integral brings u back: the result is 20 % from
    # the bound, where clamping the whole increment once would give the bound itself.
    kp, ti, ts, te = 2.0, 5.0, 10.0, 1.0
    n = 200_000
    h = ts / n
    u, m = u0, mem
    for _ in range(n):
        rate = kp * (e / ti + (e - m) / te)
        if not ((u >= 100.0 and rate > 0.0) or (u <= 0.0 and rate < 0.0)):
            u = min(max(u + h * rate, 0.0), 100.0)
        m += h * (e - m) / te
    pi = ScaledPI(Scaling(0.0, 100.0, span=100.0), kp=kp, ti=ti, ts=ts, te=te, direction=1, p0=u0)
    pi.e_mem = mem
    assert pi.update(e, 0.0) == pytest.approx(u, abs=1e-3)


def test_plant_pi_block_hold_limits_and_setpoint(fmu_cache) -> None:
    """Blocks.Validation.PIHoldAndLimits simulated (the plant-side PI, not the parameter controller).

    Hand-derived expectations: integral action brings the first-order process
    to the setpoint (0.5, then 0.9 after 200 s; both below the output limit 1);
    the setpoint step asks for k*0.4 + 0.5 = 1.3 > 1, so the output sits at its
    limit for a while and never exceeds it; while held (600-900 s) the output
    is frozen and on release it continues without a step.
    """
    from trackingbox.fmu import FMUModel

    fmu = fmu_cache("TrackingBox.Blocks.Validation.PIHoldAndLimits")
    with FMUModel(fmu, tolerance=1e-8) as model:
        df = model.simulate(stop_time=1500.0, output_interval=1.0, outputs=["con.y", "x"])
    t, y, x = df["time"].to_numpy(), df["con.y"].to_numpy(), df["x"].to_numpy()
    assert x[t == 199.0][0] == pytest.approx(0.5, abs=0.01)  # still settling from x = 0
    assert x[t == 599.0][0] == pytest.approx(0.9, abs=2e-3)
    assert y.max() <= 1.0 + 1e-9 and y.min() >= 0.0 - 1e-9
    assert np.any((t > 200.0) & (t < 260.0) & (y > 1.0 - 1e-9))  # at the limit after the step
    held = (t >= 601.0) & (t <= 899.0)
    assert np.ptp(y[held]) < 1e-5  # frozen (to the solver's crossing of the unevented switch at 600 s)
    assert abs(y[t == 902.0][0] - y[t == 899.0][0]) < 1e-3  # bumpless release


def test_parameter_controller_closed_loop_validation_model(fmu_cache) -> None:
    """Blocks.Validation.ParameterControllerLoop: the tracked gain against the hand-known truth.

    Plant and twin ``tau dx/dt = k - x``: in steady state the twin matches the
    plant only with ``k_twin = k_plant``; 4.0 is above the bound 3, so the
    output sits at 3; held, it stays there; released, it converges to 1.0
    without first winding down from a stored integral.
    """
    from trackingbox.fmu import FMUModel

    fmu = fmu_cache("TrackingBox.Blocks.Validation.ParameterControllerLoop")
    with FMUModel(fmu, tolerance=1e-8) as model:
        df = model.simulate(stop_time=6000.0, output_interval=10.0, outputs=["con.y", "xPlant", "xTwin"])
    t, k = df["time"].to_numpy(), df["con.y"].to_numpy()
    assert k[t == 1990.0][0] == pytest.approx(1.5, abs=1e-3)
    assert k[t == 3490.0][0] == pytest.approx(3.0, abs=1e-9)  # at the upper bound
    assert k.max() <= 3.0 + 1e-9 and k.min() >= 0.5 - 1e-9
    held = (t >= 3500.0) & (t <= 3990.0)
    assert np.ptp(k[held]) < 1e-6
    assert k[t == 5990.0][0] == pytest.approx(1.0, abs=1e-3)
    # no windup: after the release the output leaves the bound at once
    assert k[t == 4100.0][0] < 3.0 - 0.1


@pytest.mark.parametrize("u0, e0, e1, mem", [(1.0, 5.0, -3.0, 40.0), (99.0, -5.0, 8.0, -40.0),
                                             (99.5, 30.0, -30.0, 35.0), (50.0, 10.0, 12.0, 0.0),
                                             (2.0, -20.0, 25.0, -5.0)])
def test_linear_step_matches_a_fine_clamped_integration(u0: float, e0: float, e1: float, mem: float) -> None:
    # one sample of the block's law with the error going linearly from e0 to e1 (as the compiled box
    # sees an interpolated measurement), u clamped to 0..100 by conditional integration, integrated
    # with 200 000 explicit Euler steps; the rate changes sign once or twice in these cases.
    kp, ti, ts, te = 2.0, 5.0, 10.0, 1.0
    n = 200_000
    h = ts / n
    u, m = u0, mem
    for i in range(n):
        e = e0 + (e1 - e0) * (i * h) / ts
        rate = kp * (e / ti + (e - m) / te)
        if not ((u >= 100.0 and rate > 0.0) or (u <= 0.0 and rate < 0.0)):
            u = min(max(u + h * rate, 0.0), 100.0)
        m += h * (e - m) / te
    pi = ScaledPI(Scaling(0.0, 100.0, span=100.0), kp=kp, ti=ti, ts=ts, te=te, direction=1, p0=u0,
                  interpolation="linear")
    pi.update(e0, 0.0)  # the first call records e0
    pi.e_mem = mem
    assert pi.update(e1, 0.0) == pytest.approx(u, abs=1e-3)
    assert pi.e_mem == pytest.approx(m, abs=1e-3)


@pytest.mark.parametrize("dt, e0, e1, mem", [(2.5, 5.0, -3.0, 40.0), (4.0, -20.0, 25.0, -5.0)])
def test_linear_step_over_part_of_a_sample_matches_a_fine_integration(dt: float, e0: float, e1: float,
                                                                     mem: float) -> None:
    # the runtime's sub-steps: an update dt seconds after the previous one (dt < Ts) integrates the
    # block's law over dt, not over the sample time; reference: 100 000 explicit Euler steps over dt
    kp, ti, ts, te, u0 = 2.0, 5.0, 10.0, 1.0, 50.0
    n = 100_000
    h = dt / n
    u, m = u0, mem
    for i in range(n):
        e = e0 + (e1 - e0) * (i * h) / dt
        rate = kp * (e / ti + (e - m) / te)
        if not ((u >= 100.0 and rate > 0.0) or (u <= 0.0 and rate < 0.0)):
            u = min(max(u + h * rate, 0.0), 100.0)
        m += h * (e - m) / te
    pi = ScaledPI(Scaling(0.0, 100.0, span=100.0), kp=kp, ti=ti, ts=ts, te=te, direction=1, p0=u0,
                  interpolation="linear")
    pi.update(e0, 0.0)
    pi.e_mem = mem
    assert pi.update(e1, 0.0, dt=dt) == pytest.approx(u, abs=1e-3)
    assert pi.e_mem == pytest.approx(m, abs=1e-3)
    zoh = ScaledPI(Scaling(0.0, 100.0, span=100.0), kp=kp, ti=ti, ts=ts, direction=1, p0=u0)
    with pytest.raises(ValueError, match="zoh"):
        zoh.update(1.0, 0.0, dt=dt)  # the held error steps whole samples only
