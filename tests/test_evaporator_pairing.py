"""The evaporator's pairing rules: operating points only where the plant runs; the pump's wear in its
discharge pressure, not in the product flow, when the loops run as ``track`` runs them.

Expected values are hand-computed (the hours' means) or follow from the physics (the flash level loop
sets the product flow by the mass balance; the pump's law gives its discharge pressure), not taken
from the code's own output.
"""
from __future__ import annotations

import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trackingbox.analysis.pair_stage import running_inputs
from trackingbox.analysis.steptest import farthest_operating_point
from trackingbox.spec import Spec


def _hours_with_a_stoppage() -> tuple[types.SimpleNamespace, Spec]:
    """4 h on a 10 s grid: feed 2.0 kg/s, a stoppage (0.02 kg/s) from 4000 s to 6400 s masked with
    the settle time to 7200 s, 2.2 kg/s in the third hour, 2.0 in the fourth."""
    t = np.arange(0.0, 4 * 3600.0, 10.0)
    feed = np.where((t >= 4000.0) & (t < 6400.0), 0.02, np.where((t >= 7200.0) & (t < 10800.0), 2.2, 2.0))
    stopped = (t >= 4000.0) & (t < 7200.0)
    frame = pd.DataFrame({"time": t, "F": feed, "Y": 1.0 + 0.0 * t})
    view = types.SimpleNamespace(stopped=stopped, to_frame=lambda: frame.copy())
    spec = Spec(path=Path("s.toml"), twin=Path("t.fmu"), measurements=Path("m.csv"), sample_time=10.0,
                inputs={"F": "feedFlowSet"}, outputs={"Y": "y"})
    return view, spec


def test_second_operating_point_is_a_running_hour_not_a_stoppage() -> None:
    view, spec = _hours_with_a_stoppage()
    ref = {"feedFlowSet": 2.0}
    # all samples: the stoppage hour is furthest (mean feed (400*2.0 + 2400*0.02 + 800*2.0)/3600 by hand)
    at, values = farthest_operating_point(view.to_frame(), spec.inputs, ref, start=0.0, stop=4 * 3600.0)
    assert at == 3600.0 and values["feedFlowSet"] == pytest.approx(2448.0 / 3600.0)
    # running samples only: the second hour keeps its 400 s at 2.0 (distance 0); the third hour at 2.2
    # is the furthest, at a relative distance 0.2/2.2
    running = running_inputs(view, spec)
    assert running["Y"].notna().all(), "outputs are left as they are"
    at, values = farthest_operating_point(running, spec.inputs, ref, start=0.0, stop=4 * 3600.0)
    assert at == 7200.0 and values == {"feedFlowSet": pytest.approx(2.2)}


TWIN = "TrackingBox.Benches.Evaporator.Twin"


@pytest.mark.compile
def test_pump_wear_shows_in_the_discharge_pressure_not_the_product_flow(fmu_cache) -> None:
    """Every loop active (as the twin is tracked): a 10 % weaker pump leaves the product flow to the mass
    balance and lowers the discharge pressure by the pump law's share, dp0 (1 - (V/VMax)^2)."""
    from trackingbox.fmu import FMUModel

    out = ["FI_product", "PI_pump", "PI_flash", "ZI_product", "pump.rho", "pump.VMax"]
    ends = {}
    with FMUModel(fmu_cache(TWIN)) as m:
        for dp0 in (4.0e5, 3.6e5):
            df = m.simulate(stop_time=6 * 3600, output_interval=600, parameters={"pump.dp0": dp0}, outputs=out)
            ends[dp0] = df.iloc[-1]
    new, worn = ends[4.0e5], ends[3.6e5]
    # the flash level loop sets the product flow: the same feed and evaporation give the same flow
    assert worn["FI_product"] == pytest.approx(new["FI_product"], rel=1e-3)
    # the loop opens the product valve further to pass it against the lower head
    assert worn["ZI_product"] > new["ZI_product"] + 0.005
    # the pump law at the common flow: the discharge pressure falls by 0.4 bar x (1 - (V/VMax)^2)
    v = new["FI_product"] / new["pump.rho"]
    expected = 0.4e5 * (1.0 - (v / new["pump.VMax"]) ** 2) + (new["PI_flash"] - worn["PI_flash"])
    assert new["PI_pump"] - worn["PI_pump"] == pytest.approx(expected, rel=0.02)
