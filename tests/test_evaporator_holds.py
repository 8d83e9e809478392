"""The evaporator twin's hold inputs per controller group (step tests that keep some loops active).

Expected behaviour, not numbers from the code: a held loop's valve does not move
while the process moves; a loop left active still follows its setpoint (the inlet
flow loop: FI_feed reaches a new feed setpoint, so an inlet-valve capacity error
shows in its position); releasing a hold gives no jump.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from trackingbox.fmu import FMUModel

pytestmark = pytest.mark.compile

TWIN = "TrackingBox.Benches.Evaporator.Twin"
ZI = ["ZI_inlet", "ZI_outlet", "ZI_product", "ZI_condensate"]


def _run(fmu, holds: dict[str, float]) -> pd.DataFrame:
    """1 h settled at the design point, the holds on from 3600 s to 7200 s with a feed setpoint
    step of +10 % at 3660 s, then released until 9000 s."""
    t = [0.0, 3600.0, 3601.0, 3660.0, 3661.0, 7200.0, 7201.0, 9000.0]
    inputs = pd.DataFrame({"time": t, "feedFlowSet": [2.0, 2.0, 2.0, 2.0, 2.2, 2.2, 2.2, 2.2]})
    for name, value in holds.items():
        inputs[name] = [0.0, 0.0, value, value, value, value, 0.0, 0.0]
    with FMUModel(fmu) as m:
        return m.simulate(stop_time=9000, output_interval=10, inputs=inputs, outputs=ZI + ["FI_feed", "LI_body"])


@pytest.mark.parametrize("holds, held, active", [
    ({"holdLevelControllers": 1.0}, ["ZI_outlet", "ZI_product", "ZI_condensate"], ["ZI_inlet"]),
    ({"holdFlashLevelController": 1.0, "holdCondensateLevelController": 1.0}, ["ZI_product", "ZI_condensate"],
     ["ZI_inlet", "ZI_outlet"]),
    ({"holdFlowController": 1.0}, ["ZI_inlet"], []),
    ({"holdControllers": 1.0}, ZI, []),
], ids=["levels", "flash+condensate", "flow", "all"])
def test_group_holds_freeze_only_their_loops(fmu_cache, holds, held, active):
    df = _run(fmu_cache(TWIN), holds)
    window = df[(df.time >= 3620) & (df.time <= 7200)]
    for tag in held:
        assert np.ptp(window[tag]) < 1e-4, tag
    for tag in active:
        assert np.ptp(window[tag]) > 5e-3, tag  # the setpoint step moved the process and the loop answered
    end = window.iloc[-1]
    if "ZI_inlet" in active:
        assert end["FI_feed"] == pytest.approx(2.2, rel=2e-3)  # the flow loop follows its new setpoint
    else:
        assert abs(end["FI_feed"] - 2.2) > 0.02  # frozen inlet valve: the flow stays off the setpoint
    released = df[df.time >= 7200]
    for tag in ZI:  # bumpless release: at most 0.01 per 10 s
        assert np.abs(np.diff(released[tag].to_numpy())).max() < 0.01, tag
