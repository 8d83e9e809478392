"""The generated tracking box against the Python controller through transients.

One spec (the ``Mini`` heater of ``_fixtures_generate``), one pair whose gain
and time constant come from a step test on the compiled twin *in this test*,
one generated box compiled on its own (its inputs are the measured and the
simulated tag and the hold), and one Python :class:`ScaledPI` whose gains are
computed here by hand from the SIMC rule. Both are driven by the same data:
a start-up hold, a release, a measurement step mid-run, a hold in the middle
and its resume, saturation at the lower bound and leaving it. The parameter
TRAJECTORY is compared sample by sample, and each phase is checked against
what it must do (frozen while held, exactly at the bound while saturated,
no proportional kick at a resume, away from the bound as soon as the error
changes sign).

Change the law in the template or in ``Blocks.ParameterController`` (kp, Ti,
Te, span, direction, bounds, start, the start-up hold) and the comparison
fails: it is exact up to the integrator's tolerance.
"""
from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trackingbox.compiler import compile_model
from trackingbox.fmu import FMUModel
from trackingbox.generate.generator import _BLOCKS_LIBRARY, generate
from trackingbox.generate.source import stage_packages
from trackingbox.spec import load_spec
from trackingbox.tracking.controllers import Scaling, ScaledPI

from _fixtures_generate import write_case

# the Mini twin: C dT/dt = Qin - kht A (T - Tc); C = 4e5 J/K, A = 10 m2, Tc = 300 K
C, A, TC, QIN = 4.0e5, 10.0, 300.0, 50000.0
TS = 10.0               # the spec's sample time
HOLD_UNTIL = 300.0      # start-up hold written into the spec
P_MIN, P_MAX, P0 = 800.0, 1200.0, 1000.0


def _steady(kht: float) -> float:
    return TC + QIN / (kht * A)


def _first_order(t_prev: float, kht: float, dt: float) -> float:
    """Exact response of the Mini twin over *dt* with kht held (a first-order lag to its steady state)."""
    tau = C / (kht * A)
    return _steady(kht) + (t_prev - _steady(kht)) * math.exp(-dt / tau)


@pytest.fixture(scope="module")
def box(tmp_path_factory: pytest.TempPathFactory):
    """Step test on the compiled twin, the pair written from it, the box generated and compiled alone."""
    root = tmp_path_factory.mktemp("boxtransients")
    spec_path = write_case(root / "case", pairs=False)
    case = spec_path.parent
    twin = compile_model(case / "Mini", "Mini.Twin", backend="embedded", output=case / "twin.fmu").fmu
    # step test: settle at kht = 1000, then kht + 50 at 600 s; gain from the steady change, time
    # constant from the time to 63.2 % of it (first-order response)
    with FMUModel(twin, tolerance=1e-10) as model:
        run = model.stepper(start_time=0.0)
        run.set({"Qin": QIN})
        run.step(600.0)
        y0 = float(run.get(["ThOut"])[0])
        run.set({"hx.kht": 1050.0})
        times = np.arange(601.0, 1801.0, 1.0)
        ys = []
        for t in times:
            run.step(float(t))
            ys.append(float(run.get(["ThOut"])[0]))
    ys = np.asarray(ys)
    gain = float((ys[-1] - y0) / 50.0)
    reached = (ys - y0) / (ys[-1] - y0)
    k = int(np.argmax(reached >= 1.0 - math.exp(-1.0)))
    # linear interpolation of the crossing between the 1-s samples
    tau = float(times[k - 1] + (1.0 - math.exp(-1.0) - reached[k - 1]) / (reached[k] - reached[k - 1]) - 600.0)
    # the step test must measure the twin's physics: the secant -Q/A (1/1050 - 1/1000)/50 and C/(1050 A)
    assert gain == pytest.approx(-QIN / A * (1.0 / 1000.0 - 1.0 / 1050.0) / 50.0, rel=1e-4)
    assert tau == pytest.approx(C / (1050.0 * A), rel=2e-3)
    spec_path.write_text(spec_path.read_text() + f'''
[[pairs]]
variable = "TI-102"
parameter = "hx.kht"
gain = {gain!r}
time_constant = {tau!r}
lambda = 1.0

[tracking]
hold_until = {HOLD_UNTIL!r}
''')
    result = generate(load_spec(spec_path, check_files=False), root / "gen")
    with tempfile.TemporaryDirectory(prefix="boxtransients-") as tmp:
        stage = Path(tmp)
        pkg = stage_packages(stage, result.library, result.package_dir)
        libs = [stage / result.library.name]
        stage_packages(stage, _BLOCKS_LIBRARY(), result.package_dir)
        libs.append(stage / _BLOCKS_LIBRARY().name)
        fmu = compile_model(pkg, result.box_model, backend="embedded", output=root / "box.fmu", libraries=libs).fmu
    return {"fmu": fmu, "gain": gain, "tau": tau}


def _plant_kht(t: float) -> float:
    """The plant's heat-transfer coefficient over the run: the phases of the transient test."""
    if t < 2400.0:
        return 900.0
    if t < 4200.0:
        return 1050.0   # changes in the middle of the hold 2100-2700 s (the error grows while held)
    if t < 6000.0:
        return 700.0    # below the lower bound 800: the controller saturates
    return 950.0        # back inside: the controller must leave the bound at once


def _scenario(pi: ScaledPI) -> dict[str, np.ndarray]:
    """Run plant, twin and the Python controller in closed loop (exact first-order steps).

    Returns the sampled measurement ``u_s`` (with a -0.3 K sensor step at 1500 s),
    the twin's ``u_m``, the hold flag per sample and the controller's output.
    """
    grid = np.arange(0.0, 7200.0 + 1e-9, TS)
    hold = ((grid >= 2100.0) & (grid < 2700.0)).astype(float)
    t_plant, t_twin = _steady(900.0), _steady(P0)
    u_s, u_m, out = [], [], []
    for k, t in enumerate(grid):
        meas = t_plant - (0.3 if t >= 1500.0 else 0.0)
        u_s.append(meas)
        u_m.append(t_twin)
        p = pi.update(meas, t_twin, hold=bool(hold[k] > 0.5 or t < HOLD_UNTIL - 1e-9))
        out.append(p)
        # the twin sees, over [t_k, t_k+1), the value the controller has at t_k (a stand-in for the
        # box's continuous output: the data only have to be the same for both controllers)
        t_twin = _first_order(t_twin, p, TS)
        t_plant = _first_order(t_plant, _plant_kht(t), TS)
    return {"time": grid, "u_s": np.asarray(u_s), "u_m": np.asarray(u_m), "hold": hold, "python": np.asarray(out)}


@pytest.mark.compile
def test_generated_box_follows_the_python_controller_through_transients(box) -> None:
    gain, tau = box["gain"], box["tau"]
    # the controller settings by hand: span = |gain| (max - min), so the scaled process gain is 1;
    # SIMC with tau_c = lambda tau = tau and an effective delay of half a sample:
    # kp = tau / (tau_c + Ts/2), Ti = min(tau, 4 (tau_c + Ts/2)) = tau; Te = Ts/10
    span = abs(gain) * (P_MAX - P_MIN)
    kp, ti = tau / (tau + TS / 2.0), tau
    pi = ScaledPI(Scaling(P_MIN, P_MAX, span=span), kp=kp, ti=ti, ts=TS, te=TS / 10.0, direction=-1, p0=P0,
                  interpolation="linear")
    data = _scenario(pi)
    grid = data["time"]
    table = pd.DataFrame({"time": grid, "TI_102_meas": data["u_s"], "TI_102_sim": data["u_m"]})
    mo = []
    with FMUModel(box["fmu"], tolerance=1e-10) as model:
        run = model.stepper(start_time=0.0, inputs=table)
        for k in range(grid.size):
            mo.append(float(run.get(["hx_kht"])[0]))
            if k + 1 < grid.size:
                run.set({"hold": float(data["hold"][k])})  # held over the sample, as validate feeds it
                run.step(float(grid[k + 1]))
    mo_a, py_a = np.asarray(mo), data["python"]
    rng = P_MAX - P_MIN

    # the trajectory: box and Python controller, sample by sample. Both are exact solutions of the
    # same law for an error linear between samples; the FMU integrates it with CVODE at 1e-10 and
    # restarts at each hold switch, so 1e-6 of the bound range leaves two decades of margin. A 20 %
    # change of kp moves the output by about kp Δe/5 at every error change: tens of percent of it.
    diff = np.abs(mo_a - py_a) / rng
    assert diff.max() <= 1e-6, (diff.max(), float(grid[int(diff.argmax())]))

    # what each phase must do (hand expectations on the box's own trajectory)
    start = grid < HOLD_UNTIL
    assert np.all(mo_a[start] == P0)                                  # start-up hold: not a digit moves
    assert mo_a[grid == HOLD_UNTIL + 3 * TS][0] < P0 - 20.0          # released: moves towards 900 at once
    before_step = (grid >= 1300.0) & (grid <= 1490.0)
    assert mo_a[before_step] == pytest.approx(900.0, abs=2.0)        # converged on the plant's 900
    # the -0.3 K sensor step: the kht that explains T = 305.556 - 0.3 K is Q/(A (T - Tc))
    assert mo_a[(grid >= 1950.0) & (grid <= 2090.0)] == pytest.approx(
        QIN / (A * (_steady(900.0) - 0.3 - TC)), abs=2.0)
    held = (grid >= 2110.0) & (grid <= 2700.0)
    assert np.ptp(mo_a[held]) <= 1e-9 * rng                           # frozen through the hold
    # bumpless resume: the error memory followed the error through the hold, so over the first sample
    # after it the output moves by the integral of the (linear) error, kp Ts/Ti times its mean, plus
    # the proportional part of the error's change over that sample, kp Δe (1 - Te/Ts (1 - exp(-Ts/Te)))
    # (the memory lags a ramp by its slope times Te). A memory frozen with the output would add a kick
    # of kp times the whole error built up during the hold.
    k1 = int(np.flatnonzero(grid == 2700.0)[0])
    e = 100.0 * (data["u_s"] - data["u_m"]) / span
    te = TS / 10.0
    expected = -(kp * TS / ti * 0.5 * (e[k1] + e[k1 + 1])
                 + kp * (e[k1 + 1] - e[k1]) * (1.0 - te / TS * (1.0 - math.exp(-TS / te)))) / 100.0 * rng
    assert abs(e[k1]) > 20.0  # the hold did build up an error (the plant moved to 1050 while held)
    assert mo_a[k1 + 1] - mo_a[k1] == pytest.approx(expected, rel=0.02)
    sat = (grid >= 4800.0) & (grid < 6000.0)
    assert np.all(mo_a[sat] == pytest.approx(P_MIN, abs=1e-9 * rng))  # at the bound, not below it
    k2 = int(np.flatnonzero(grid == 6000.0)[0])
    # leaving the bound: the plant is back to 950 at 6000 s; the measurement moves within a sample
    # and the output leaves 800 within three samples (no stored integral to wind down)
    assert mo_a[k2 + 3] > P_MIN + 5.0
    # and settles on the kht that explains the plant's 950 seen through the -0.3 K sensor step
    assert mo_a[-1] == pytest.approx(QIN / (A * (_steady(950.0) - 0.3 - TC)), abs=2.0)
    assert mo_a.min() >= P_MIN - 1e-9 and mo_a.max() <= P_MAX + 1e-9
