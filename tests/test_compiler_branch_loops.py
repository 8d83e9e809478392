"""An algebraic loop follows the root it is on (its branch) and leaves it only at an event where the
branch ends (issue 35: MSL ``Electrical.Analog.Examples.OpAmps.Multivibrator`` and
``AmplifierWithOpAmpDetailed``). Before, the FMU kept every evaluation's solution as the next guess, the
integrator's trial points included: a trial step past the Schmitt trigger's threshold flipped the op-amp
early (at 7.1 V instead of 7.5 V, 10.6 Hz instead of 10 Hz), and at tight tolerances CVODE's error or
corrector test failed at the flip.

The expectations are independent of the compiler: the trigger's thresholds and period in closed form
from the circuit (an op-amp of gain V0 limited to +-Vs with positive feedback through a divider beta,
its inverting input on an RC), scipy's ``solve_ivp`` on the RC with the hysteresis written out as
events, and the inverting amplifier's gain and clipping from its resistors and output stage."""
from __future__ import annotations

import ctypes
import math

import fmpy
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Model
from scipy.integrate import solve_ivp

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile

V0, VS, BETA, R = 15000.0, 15.0, 0.5, 1000.0
C = 1 / (2 * 10 * R * math.log(3))  # the MSL example's capacitance for 10 Hz with an ideal trigger
RC = R * C
VT = BETA * VS - VS / V0  # the saturated output stays a root while V0*(beta*Vs - |vc|) >= Vs: 7.499 V
PERIOD = 2 * RC * math.log((VS + VT) / (VS - VT))  # charging from -VT to +VT toward +Vs, and back
FIRST = RC * math.log((VS + 1) / (VS - VT))  # from vc = 1 toward -Vs down to -VT

SCHMITT = """model Schmitt "an op-amp with positive feedback through a 1:1 divider, its inverting input on an RC"
  parameter Real V0 = 15000 "open-loop gain";
  parameter Real Vs = 15 "supply";
  parameter Real R = 1000;
  parameter Real C = 1/(2*10*R*log(3));
  Real vc(start = 1, fixed = true) "the capacitor";
  Real vout(start = -15) "the op-amp's output";
  Real vp "the non-inverting input";
equation
  vp = vout/2;
  vout = smooth(0, noEvent(if V0*(vp - vc) > Vs then Vs else if V0*(vp - vc) < -Vs then -Vs else V0*(vp - vc)));
  C*der(vc) = (vout - vc)/R;
end Schmitt;
"""


def _reference(stop: float):
    """The RC with the trigger's hysteresis as events (scipy): (dense vc(t), the flip times)."""
    ts, pieces, flips, t0, vc0, out = [], [], [], 0.0, 1.0, -VS
    while t0 < stop:
        def cross(_t, y, out=out):
            return y[0] + VT if out < 0 else y[0] - VT
        cross.terminal = True
        sol = solve_ivp(lambda _t, y, out=out: [(out - y[0]) / RC], (t0, stop), [vc0], events=cross,
                        dense_output=True, rtol=1e-11, atol=1e-12)
        pieces.append(sol.sol)
        ts.append(sol.t[-1])
        if sol.t_events[0].size == 0:
            break
        t0, vc0, out = sol.t_events[0][0], sol.y_events[0][0][0], -out
        flips.append(t0)
    ends = np.array(ts)

    def vc(t):
        t = np.asarray(t)
        idx = np.minimum(np.searchsorted(ends, t), len(pieces) - 1)
        return np.array([pieces[i](x)[0] for i, x in zip(idx, t)])
    return vc, np.array(flips)


def _flips(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The output times just after the output changed sign."""
    return t[1:][np.diff(np.sign(v)) != 0]


def test_the_closed_form_and_the_reference_agree():
    """(the expectations' own check) the hysteresis reference flips at FIRST, then every PERIOD / 2."""
    _, flips = _reference(0.45)
    assert flips[0] == pytest.approx(FIRST, abs=1e-9)
    assert np.allclose(np.diff(flips), PERIOD / 2, rtol=0, atol=1e-9)
    assert PERIOD == pytest.approx(0.099984, abs=1e-6)  # 2 RC ln(22.499/7.501), RC = 1/(20 ln 3)


@pytest.fixture(scope="module")
def schmitt(tmp_path_factory) -> str:
    folder = tmp_path_factory.mktemp("schmitt")
    src = folder / "Schmitt.mo"
    src.write_text(SCHMITT)
    return str(compile_model(src, "Schmitt", backend="embedded", output=folder / "Schmitt.fmu").fmu)


@pytest.mark.parametrize("rtol", [1e-6, 1e-8])
def test_a_schmitt_trigger_flips_at_its_thresholds(schmitt, rtol):
    """The small trigger to t = 0.45 s: the capacitor's voltage within 200 rtol Vs of the hysteresis
    reference at every output, the output at +-Vs flipping within 1e-6 s of the reference's flips (each
    flip is an event, recorded at its time; at 1e-8 CVODE's corrector failed at the first flip before)."""
    out = fmpy.simulate_fmu(schmitt, stop_time=0.45, output_interval=1e-4, relative_tolerance=rtol,
                            output=["vc", "vout"])
    t, vc, vout = out["time"], out["vc"], out["vout"]
    ref_vc, ref_flips = _reference(0.45)
    assert np.max(np.abs(vc - ref_vc(t))) < 200 * rtol * VS
    # (at each event's time the output is also recorded just before it: where the branch ended, 2e-5 V out)
    assert np.allclose(np.abs(vout), VS, rtol=0, atol=1e-4)
    assert np.mean(np.abs(np.abs(vout) - VS) < 1e-9) > 0.99
    flips = _flips(t, vout)
    assert len(flips) == len(ref_flips) == 9
    assert np.allclose(flips, ref_flips, rtol=0, atol=1e-6)


def _instance(fmu: str):
    md = read_model_description(fmu)
    inst = FMU3Model(guid=md.guid, unzipDirectory=extract(fmu), modelIdentifier=md.modelExchange.modelIdentifier,
                     instanceName="probe")
    inst.instantiate()
    inst.enterInitializationMode()
    inst.exitInitializationMode()
    inst.enterContinuousTimeMode()
    refs = {v.name: v.valueReference for v in md.modelVariables}
    return inst, refs


def test_a_trial_point_past_the_threshold_does_not_move_the_branch(schmitt):
    """The integrator's trial points do not move what the loop follows: at vc = -7 (output at -Vs), then a
    trial at vc = -8 (past the threshold: only +Vs is a root there), then vc = -7 again, the output and
    der(vc) = (vout - vc)/RC are those of -Vs both times (before: +Vs the second time, the flip at 7.1 V);
    a completed integrator step at vc = -8 takes the root there, +Vs."""
    inst, refs = _instance(schmitt)

    def at(vc: float) -> tuple[float, float]:
        inst.setContinuousStates((ctypes.c_double * 1)(vc), 1)
        vout, der = inst.getFloat64([refs["vout"], refs["der(vc)"]])
        return vout, der

    for vc in (-7.0, -8.0, -7.0):
        vout, der = at(vc)
        if vc == -7.0:
            assert vout == pytest.approx(-VS, abs=1e-9)
            assert der == pytest.approx((-VS - vc) / RC, rel=1e-9)
    inst.setContinuousStates((ctypes.c_double * 1)(-8.0), 1)
    inst.completedIntegratorStep()
    vout, der = at(-7.0)  # the kept root at vc = -8 is +Vs; at -7 +Vs is a root too (the upper branch)
    assert vout == pytest.approx(VS, abs=1e-9)
    assert der == pytest.approx((VS + 7.0) / RC, rel=1e-9)
    inst.terminate()
    inst.freeInstance()


def _msl_fmu(tmp_path, model: str) -> str:
    need_msl()
    return str(compile_model(MSL, model, backend="embedded", output=tmp_path / "m.fmu").fmu)


def test_the_msl_multivibrator_oscillates_at_its_designed_frequency(tmp_path):
    """``OpAmps.Multivibrator`` at the harness's tolerance 1e-7 to t = 0.45 s: the output flips at the
    closed-form times FIRST + k PERIOD / 2 (10 Hz less the 1 mV the op-amp's finite gain takes off the
    thresholds) within 1e-6 s (each flip an event, recorded at its time), and the capacitor's voltage
    there is +-VT (before: 7.1-7.2 V, 10.6 Hz, and CVODE failed at the first flip)."""
    fmu = _msl_fmu(tmp_path, "Modelica.Electrical.Analog.Examples.OpAmps.Multivibrator")
    out = fmpy.simulate_fmu(fmu, stop_time=0.45, output_interval=1e-4, relative_tolerance=1e-7,
                            output=["c.v", "opAmp.v_out"])
    t, cv, vout = out["time"], out["c.v"], out["opAmp.v_out"]
    flips = _flips(t, vout)
    expected = FIRST + PERIOD / 2 * np.arange(len(flips))
    assert len(flips) == 9
    assert np.allclose(flips, expected, rtol=0, atol=1e-6)
    at_flip = cv[1:][np.diff(np.sign(vout)) != 0]
    assert np.allclose(np.abs(at_flip), VT, rtol=0, atol=1e-4)


def test_the_msl_amplifier_with_the_detailed_op_amp_amplifies_by_minus_two_and_clips(tmp_path):
    """``AmplifierWithOpAmpDetailed`` (12 V, 1 kHz into R = 10 kOhm, feedback 20 kOhm, load 10 kOhm, supplies
    +-15 V) at its experiment's tolerance 2e-7 and at 1e-6 (CVODE's error test failed at 0.9 ms and 2.4 ms
    before): where |vin| < 6 V the output is -2 vin within 0.08 V (the finite gain-bandwidth, 10^(106/20) *
    5 Hz = 1 MHz, lags the noise gain 3 by 3 f / GBW: 24 V * 3e-3 = 0.072 V, and the 1 mV offset times 3);
    where |vin| > 10 V it is clipped: the output stage's source at the supply through Rout = 75 Ohm into
    the 10 kOhm load and the 30 kOhm back to the source, vout = (-+15/75 + vin/3e4) / (1/75 + 1/1e4 + 1/3e4),
    within 1 mV (the op-amp's input currents and the integrator's tolerance; measured 0.17 mV at 2e-7 and
    0.31 mV at 1e-6)."""
    fmu = _msl_fmu(tmp_path, "Modelica.Electrical.Analog.Examples.AmplifierWithOpAmpDetailed")
    for rtol in (2e-7, 1e-6):
        out = fmpy.simulate_fmu(fmu, stop_time=0.003, output_interval=1.2e-6, relative_tolerance=rtol,
                                output=["sineVoltage.v", "resistor2.v"])
        t, vin, vout = out["time"], out["sineVoltage.v"], out["resistor2.v"]
        assert t[-1] == pytest.approx(0.003)
        linear = (np.abs(vin) < 6) & (t > 2e-4)
        assert np.max(np.abs(vout + 2 * vin)[linear]) < 0.08
        clipped = np.abs(vin) > 10
        source = -np.sign(vin[clipped]) * VS
        expected = (source / 75 + vin[clipped] / 3e4) / (1 / 75 + 1 / 1e4 + 1 / 3e4)
        assert np.max(np.abs(vout[clipped] - expected)) < 1e-3


def test_the_pieces_of_a_loop_are_its_relations_outcomes():
    """The piece a point is on: one outcome per relation left in the residual (a min or max as whether
    its first argument is the smaller), here read off by hand at two points."""
    import casadi as ca

    from trackingbox.compiler.loop_solve import _pieces

    z, p = ca.MX.sym("z", 2), ca.MX.sym("p", 1)
    g = ca.vertcat(ca.if_else(z[0] < p, z[0], 2 * z[0]) - z[1], ca.fmin(z[1], 3) + z[0] - p)
    pieces = _pieces("t", g, z, p)
    assert sorted(np.ravel(pieces([1, 5], 2)).tolist()) == [1, 1]  # 1 < 2; min(5, 3): 3 <= 5
    assert sorted(np.ravel(pieces([3, 2], 2)).tolist()) == [0, 0]  # 3 >= 2; min(2, 3): not 3 <= 2


def test_a_loop_on_one_piece_takes_newtons_root_from_a_memory_far_from_it():
    """Between events, with the memory a whole output interval behind (it is kept at accepted points
    only), a loop whose relations are the same at the memory and at Newton's root from it (the piece of a
    current limiter is unchanged) takes that root: i = v/R on the linear piece, Imax on the limited one,
    and the branch's indicator stays positive."""
    import casadi as ca

    from trackingbox.compiler.loop_solve import branch_solution

    z, p = ca.MX.sym("z", 1), ca.MX.sym("p", 1)
    v, r, imax = p[0], 2.0, 10.0
    g = ca.if_else(z[0] < imax, r * z[0] - v, z[0] - imax)  # i = min(v/R, Imax), its relation in i
    memory, held = ca.MX.sym("m", 1), ca.MX.sym("h")
    sol, indicator = branch_solution("t", z, p, g, memory, ca.DM([0.0]), p, [-math.inf], [math.inf], held)
    f = ca.Function("f", [p, memory, held], [sol, indicator])
    for volts, remembered in ((7.0, 1.0), (30.0, 11.0), (1.0, 0.2)):  # memory and root on one piece
        i, ind = (float(x) for x in f(volts, remembered, 1))
        assert i == pytest.approx(min(volts / r, imax), rel=1e-12)
        assert ind > 0


def test_only_a_relation_of_the_unknowns_makes_branches():
    """A relation (or min/max) whose arguments are the loop's other inputs only (a parameter, a state,
    time) has one outcome in each solve, and the residual is smooth in the unknowns there: no branch, no
    event indicator (the heat-production twin's medium range fmax(0, T - 273.15) took the native
    stepper with two indicators); one of an unknown, or of an unknown and an input, makes branches."""
    import casadi as ca

    from trackingbox.compiler.loop_solve import switches

    z, p = ca.MX.sym("z", 2), ca.MX.sym("p", 2)
    smooth = ca.vertcat(z[0] - z[1] ** 3 - ca.fmax(p[0], 0), z[1] - ca.if_else(p[1] < 1, p[0], 2 * p[0]) + z[0])
    assert not switches(smooth, z)
    assert switches(smooth + ca.vertcat(ca.fmin(z[1], 3), 0), z)
    assert switches(smooth + ca.vertcat(0, ca.if_else(z[0] < p[1], 1, 0)), z)


STATE_LIMITED = """model StateLimited "an algebraic loop whose only relation is of a state"
  Real x(start = -1, fixed = true);
  Real a(start = 0.5);
  Real b;
equation
  der(x) = 1;
  b = 1 - a;
  a = b^3 + noEvent(max(x, 0));
end StateLimited;
"""


def test_a_loop_with_a_relation_of_a_state_only_has_no_event_indicator(tmp_path):
    """The loop a = (1 - a)^3 + max(x, 0), x = t - 1, compiled: no event indicator (the FMU keeps a
    native stepper), and a at every output is the root scipy's brentq finds (a - (1 - a)^3 increases
    strictly: one root), within 1e-8, on both sides of the kink at t = 1."""
    from scipy.optimize import brentq

    src = tmp_path / "StateLimited.mo"
    src.write_text(STATE_LIMITED)
    fmu = str(compile_model(src, "StateLimited", backend="embedded", output=tmp_path / "s.fmu").fmu)
    assert read_model_description(fmu).numberOfEventIndicators == 0
    out = fmpy.simulate_fmu(fmu, stop_time=2.0, output_interval=0.05, relative_tolerance=1e-8, output=["a"])
    expected = [brentq(lambda a, s=max(t - 1, 0.0): a - (1 - a) ** 3 - s, -10, 10, xtol=1e-14) for t in out["time"]]
    assert np.max(np.abs(out["a"] - np.array(expected))) < 1e-8
