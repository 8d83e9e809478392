"""The model-error part read along a held parameter's direction (issue 31, :func:`trackingbox.identify.misfit.held_gains`).

The twin, linear with first-order lags (TAU = 100 s, input ``u`` = 10): ``y1 = u + a + q``, ``y3 = 0.5 a + 2 q``.
It tracks ``a`` on Y1; Y3 is measured and no pair tracks it. It holds ``q`` at its estimate 0 with the interval
``[-0.25, 0.25]``, which misses the plant's ``q = 0.75`` (an estimate off beyond its interval). Worked by hand:

* the loop drives ``a + q`` to the plant's ``2 + 0.75``: ``a`` settles at 2.75, 0.75 above its truth 2;
* the fixed part puts the truth ``∓0.25`` from ``a`` (``-Δy/gain`` at the interval's ends): the band misses it;
* Y3 reads ``1 + 1.5 = 2.5`` on the plant, ``1.375`` on the twin: ``m = 1.125``. Read as ``a`` alone (gain 0.5) it
  puts the truth 2.25 *above* ``a``; read along ``q`` (the loop shifts ``a`` by ``s = -1`` per unit of ``q``, and
  Y3 then moves by ``2 + 0.5 s = 1.5``, a gain of ``1.5 / s = -1.5`` per unit of ``a``) it gives ``δ = 0.75`` and the
  truth ``s δ = -0.75`` from ``a``: exactly 2.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_casadi import build_casadi_fmu

TAU = 100.0
U = 10.0
A_PLANT, Q_PLANT = 2.0, 0.75
STOP = 20000.0
AFTER = 10800.0  # an hour of fast error and the 2 h mean known (bands.FIT_MEMORY)


@pytest.fixture(scope="module")
def spec(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from trackingbox.fmu import FMUModel

    fmu = build_casadi_fmu(tmp_path_factory.mktemp("held_misfit_fmu"), "heldmisfit", constants={"TAU": TAU},
                           variables=[
        ("a", ("parameter", "tunable"), {"start": 2.5, "min": 0.0, "max": 6.0}),
        ("q", ("parameter", "tunable"), {"start": 0.0, "min": -5.0, "max": 5.0}),
        ("u", ("input",), {"start": U}),
        ("x1", ("local", "continuous"), {"start": 12.5, "initial": "exact"}),
        ("x3", ("local", "continuous"), {"start": 1.25, "initial": "exact"}),
        ("y1", ("output",), {}),
        ("y3", ("output",), {}),
    ], equations=[("der(x1)", "(u + a + q - x1) / TAU"), ("der(x3)", "(0.5 * a + 2 * q - x3) / TAU"),
                  ("y1", "x1"), ("y3", "x3")])
    out = tmp_path_factory.mktemp("held_misfit_plant")
    t = np.arange(0.0, STOP + 1.0, 10.0)
    with FMUModel(fmu) as m:
        sim = m.simulate(stop_time=STOP, output_interval=10.0, inputs=pd.DataFrame({"time": t, "u": np.full(t.size, U)}),
                         parameters={"a": A_PLANT, "q": Q_PLANT, "x1": U + A_PLANT + Q_PLANT,
                                     "x3": 0.5 * A_PLANT + 2 * Q_PLANT}, outputs=["y1", "y3"])
    rng = np.random.default_rng(8)
    pd.DataFrame({"time": t, "FI": np.full(t.size, U), "Y1": sim["y1"].to_numpy() + rng.normal(0.0, 0.02, t.size),
                  "Y3": sim["y3"].to_numpy() + rng.normal(0.0, 0.02, t.size)}).to_csv(out / "m.csv", index=False)
    text = (f'twin = "{fmu}"\nmeasurements = "{out / "m.csv"}"\nsample_time = 10.0\n\n'
            '[inputs]\nFI = "u"\n\n[outputs]\nY1 = "y1"\nY3 = "y3"\n\n'
            '[[parameters]]\nname = "a"\nstart = 2.5\nmin = 0.0\nmax = 6.0\n\n'
            "[fixed]\nq = 0.0\n\n[fixed_intervals]\nq = [-0.25, 0.25]\n\n"
            "[windows]\ntraining = [0.0, 10000.0]\nvalidation = [10000.0, 20000.0]\n\n"
            f'[[pairs]]\nvariable = "Y1"\nparameter = "a"\ngain = 1.0\ntime_constant = {TAU!r}\nlambda = 1.0\n\n'
            "[tracking]\nhold_until = 200.0\n")
    (out / "spec.toml").write_text(text, encoding="utf-8")
    return out / "spec.toml"


def test_held_rows_are_the_tags_gain_along_the_held_direction(spec: Path) -> None:
    from trackingbox.identify.held import band_parts
    from trackingbox.spec import load_spec

    fixed, _, _, misfit = band_parts(load_spec(spec))
    assert [(f.name, f.at_lower, f.at_upper) for f in fixed["a"]] == [("q", pytest.approx(0.25, rel=0.02),
                                                                      pytest.approx(-0.25, rel=0.02))]
    own, along_q = misfit["Y3"]
    assert own == [pytest.approx(0.5, rel=0.02)] and along_q == [pytest.approx(-1.5, rel=0.02)]


def test_track_band_holds_the_truth_a_held_estimate_off_beyond_its_interval_put_the_loop_from(spec: Path,
                                                                                            tmp_path: Path) -> None:
    from trackingbox.commands import track as track_command
    from trackingbox.identify.bands import BandTracker
    from trackingbox.identify.held import band_parts
    from trackingbox.spec import load_spec

    parser = argparse.ArgumentParser(prog="trackingbox")
    track_command.register(parser.add_subparsers())
    assert track_command.run(parser.parse_args(["track", str(spec), "--out", str(tmp_path)])) == 0
    df, result = pd.read_csv(tmp_path / "tracking.csv"), json.loads((tmp_path / "result.json").read_text())
    rows = df[(df["time"] >= AFTER) & df["parameter_lo:a"].notna()]
    assert len(rows) > 900
    assert float(rows["parameter:a"].mean()) == pytest.approx(A_PLANT + Q_PLANT, abs=0.02)  # 0.75 above the truth
    assert float(((rows["parameter_lo:a"] <= A_PLANT) & (A_PLANT <= rows["parameter_hi:a"])).mean()) >= 0.95
    assert result["bands"]["a"]["model_error"]["held_readings"] == 1
    # the same run's bands with Y3 read as ``a`` alone: the fixed part's 0.25 and Y3's reading above miss the truth
    loaded = load_spec(spec)
    fixed, note, gains, misfit = band_parts(loaded)
    base = [c for c in df.columns if not c.startswith(("parameter_lo:", "parameter_hi:", "lack_of_fit"))]
    numbers = df[base].copy()
    numbers["mode:Y1"] = (df["mode:Y1"].astype(str) == "hold").astype(float)
    alone = BandTracker(loaded, base, fixed=fixed, note=note, gains=gains, misfit={"Y3": misfit["Y3"][0]})
    out = pd.DataFrame(alone.rows(numbers.to_numpy(float)), columns=alone.columns)
    sel = ((df["time"] >= AFTER) & out["parameter_lo:a"].notna()).to_numpy()
    assert float(((out["parameter_lo:a"] <= A_PLANT) & (A_PLANT <= out["parameter_hi:a"]))[sel].mean()) < 0.05
