"""The event iteration's search for a consistent set of relations accepts one that reproduces itself
up to ties: a relation whose operands come out equal (within the indicators' hysteresis) keeps the
value it was given. The MSL's ``LossyGear`` meets such a tie where its sliding and break-away torques
are equal: each value of the relation selects the other, and before, the event iteration never
settled (``Rotational.Examples.LossyGearDemo2`` stopped at t = 0.31 s, ``LossyGearDemo3`` at its
initialisation). Checked against physics independent of the code: the gear's efficiency (a rolling
gear with mesh efficiency eta loses 1 - eta of the driving side's power), the second law (no
negative loss) and the energy balance of the free-running phase (kinetic energy lost = heat)."""
from __future__ import annotations

import fmpy
import numpy as np
import pytest

from _fixtures_msl import MSL, need_msl
from trackingbox.compiler import compile_model

pytestmark = pytest.mark.compile


def test_msl_lossy_gear_demo2_runs_to_its_end_losing_half_the_driving_power(tmp_path):
    """LossyGearDemo2: gear ratio 2, lossTable [0, 0.5, 0.5, 0, 0] (mesh efficiency 0.5 whichever
    side drives, no bearing friction in the gear). Rolling, the gear loses half the power that
    enters it: PowerLoss = 0.5 max(|P_a|, |P_b|) (0 where it is stuck)."""
    need_msl()
    fmu = compile_model(MSL, "Modelica.Mechanics.Rotational.Examples.LossyGearDemo2", backend="embedded",
                        output=tmp_path / "lgd2.fmu").fmu
    names = ["PowerLoss", "gear.flange_a.tau", "gear.flange_b.tau", "Inertia1.w", "Inertia2.w"]
    out = fmpy.simulate_fmu(str(fmu), stop_time=0.5, output_interval=0.001, relative_tolerance=1e-8,
                            output=names)
    assert out["time"][-1] == pytest.approx(0.5)
    pa = out["gear.flange_a.tau"] * out["Inertia1.w"]
    pb = out["gear.flange_b.tau"] * out["Inertia2.w"]
    loss = out["PowerLoss"]
    assert loss.min() > -1e-6
    expect = 0.5 * np.maximum(np.abs(pa), np.abs(pb))  # 0 where the gear is stuck
    assert np.max(expect) > 0.01
    assert np.max(np.abs(loss - expect)) < 1e-4 * max(1.0, np.max(expect))


def test_msl_lossy_gear_demo3_initialises_and_heats_by_the_kinetic_energy_it_loses(tmp_path):
    """LossyGearDemo3: two inertias of 0.001 kg m2 on a gear of ratio 1 (efficiency 0.25, bearing
    friction 0.625 / 2.5 N m), the first spinning at 10 rad/s, no torque until t = 0.5 s. Until
    then the gear's heat is the kinetic energy the inertias lose, and the speed only falls."""
    need_msl()
    fmu = compile_model(MSL, "Modelica.Mechanics.Rotational.Examples.LossyGearDemo3", backend="embedded",
                        output=tmp_path / "lgd3.fmu").fmu
    out = fmpy.simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.001, relative_tolerance=1e-8,
                            output=["gear.lossPower", "Inertia1.w", "Inertia2.w"])
    t = out["time"]
    assert t[-1] == pytest.approx(1.0)
    w1, w2, loss = out["Inertia1.w"], out["Inertia2.w"], out["gear.lossPower"]
    assert np.max(np.abs(w1 - w2)) < 1e-6  # ratio 1
    assert loss.min() > -1e-6
    free = t < 0.5 - 1e-9
    assert w1[0] == pytest.approx(10.0) and np.all(np.diff(w1[free]) <= 1e-9)
    energy = 0.5 * (0.001 + 0.001) * w1 ** 2
    heat = np.concatenate([[0.0], np.cumsum(0.5 * (loss[1:] + loss[:-1]) * np.diff(t))])
    k = np.flatnonzero(free)[-1]
    assert energy[0] - energy[k] > 0.01  # it does slow down
    assert heat[k] == pytest.approx(energy[0] - energy[k], rel=1e-3)
