"""Estimation, tracking and validation score exactly the same samples of one spec.

The case: the ``Mini`` heater of ``_fixtures_generate`` as plant (``kht = 900``)
and twin (``kht = 1000``), measured with

* irregular per-tag sampling: the heater power ``QI-100`` (the twin's input)
  every 30 s, the temperature ``TI-102`` every 20 s with timestamps
  alternately 3 s late and early (so never on the 10 s grid), in one CSV with
  empty cells (its last sample, at 7203 s, closes the window);
* a long gap: ``TI-102`` has no sample from 3500 s to 4100 s;
* a stoppage: the heater is off (``QI-100`` = 0) from 5000 s to 5300 s
  (``below = 27500`` W, half its power then; ``settle = 120 s``).

Expected by hand, on the 10 s grid of the validation window [3600, 7200) s:

* the gap: the last ``TI-102`` sample before it is at 3497 s (j = 175,
  20 j - 3), the first after it at 4123 s (j = 206, 20 j + 3); grid points
  strictly between are missing data (626 s is far beyond 2.5 x the tag's
  20 s median interval), in the window 3600 .. 4120 s: 53 points;
* the stoppage: ``QI-100`` interpolated between its 30 s samples is 2/3 of
  55 kW at 4990 s (4980: 55 kW, 5010: 0), 1/3 at 5000 s, 1/3 at 5290 s
  (5280: 0, 5310: 55 kW) and 2/3 at 5300 s, so 5000 .. 5290 s are stopped, and with the settle time
  the mask runs to 5290 + 120 = 5410 s: 42 points;
* everything else is scored: 360 - 53 - 42 = 265 points.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from _fixtures_generate import write_case

TAG = "TI-102"
WINDOW = (3600.0, 7200.0)


def _expected_mask(grid: np.ndarray) -> np.ndarray:
    in_window = (grid >= WINDOW[0]) & (grid < WINDOW[1])
    hole = (grid > 3497.0) & (grid < 4123.0)
    stopped = (grid >= 5000.0) & (grid <= 5410.0)
    return in_window & ~hole & ~stopped


def _nrmse(sim: np.ndarray, meas: np.ndarray) -> float:
    err = sim - meas
    return float(np.sqrt(np.mean(err * err)) / (meas.max() - meas.min()))


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> dict:
    from trackingbox.compiler import compile_model
    from trackingbox.fmu import FMUModel
    from trackingbox.generate.generator import compile_generated, generate
    from trackingbox.spec import load_spec

    root = tmp_path_factory.mktemp("same")
    spec_path = write_case(root / "case", gains="")
    case_dir = spec_path.parent
    compile_model(case_dir / "Mini", "Mini.Twin", backend="embedded", output=case_dir / "twin.fmu")
    fine = np.arange(0.0, 7210.0, 1.0)
    qin = np.where(fine < 2400.0, 50000.0, np.where(fine < 4800.0, 40000.0, 55000.0))
    qin[(fine >= 5000.0) & (fine < 5300.0)] = 0.0
    with FMUModel(case_dir / "twin.fmu") as plant:
        sim = plant.simulate(stop_time=7210.0, output_interval=1.0, parameters={"hx.kht": 900.0},
                             inputs=pd.DataFrame({"time": fine, "Qin": qin}), outputs=["ThOut"])
    t_plant = sim["time"].to_numpy()
    temp = sim["ThOut"].to_numpy()
    j = np.arange(0, 361)
    t_ti = 20.0 * j + np.where(j % 2 == 0, 3.0, -3.0)
    t_ti = t_ti[(t_ti >= 0.0) & ((t_ti < 3500.0) | (t_ti >= 4100.0)) & (t_ti <= 7205.0)]
    t_qi = np.arange(0.0, 7201.0, 30.0)
    times = np.union1d(t_ti, t_qi)
    frame = pd.DataFrame({"time": times})
    frame["QI-100"] = np.where(np.isin(times, t_qi), np.interp(times, fine, qin), np.nan)
    frame[TAG] = np.where(np.isin(times, t_ti), np.interp(times, t_plant, temp), np.nan)
    frame.to_csv(case_dir / "measurements.csv", index=False, na_rep="")
    with open(spec_path, "a", encoding="utf-8") as fh:
        fh.write('\n[data]\nstoppage = { tag = "QI-100", below = 27500.0, settle = 120.0 }\n\n'
                 "[tracking]\nhold_until = 600.0\n")
    spec = load_spec(spec_path)
    gen = generate(spec, case_dir / "generated")
    tracked = compile_generated(gen, backend="embedded").fmu
    return {"spec": spec, "fmu": tracked, "root": root}


@pytest.mark.compile
def test_estimation_tracking_and_validation_score_the_same_samples(case: dict) -> None:
    from trackingbox.estimation import load_windows
    from trackingbox.tracking.runtime import track
    from trackingbox.validate import validate

    spec = case["spec"]
    # estimation: the validation window's cost samples
    _, val = load_windows(spec)
    est_times = val.time[np.isfinite(val.measured[TAG])]
    grid = np.arange(0.0, 7200.0, 10.0)
    expected = grid[_expected_mask(grid)]
    assert expected.size == 265
    np.testing.assert_array_equal(est_times, expected)

    # tracking: the NRMSE figures are taken over exactly those samples
    tr = track(spec, out_dir=case["root"] / "track", window="validation")
    df = pd.read_csv(tr.csv)
    assert df["time"].tolist() == grid.tolist()
    mask = _expected_mask(df["time"].to_numpy())
    meas = df[f"measured:{TAG}"].to_numpy()
    assert np.isfinite(meas[mask]).all()
    assert tr.variables[TAG].samples == 265
    assert tr.variables[TAG].nrmse_tracked == pytest.approx(
        _nrmse(df[f"tracked:{TAG}"].to_numpy()[mask], meas[mask]), rel=1e-9)
    assert tr.variables[TAG].nrmse_untracked == pytest.approx(
        _nrmse(df[f"untracked:{TAG}"].to_numpy()[mask], meas[mask]), rel=1e-9)
    # the controllers hold in the gap and the stoppage
    held = ~np.isfinite(meas) | ((df["time"] >= 5000.0) & (df["time"] <= 5410.0)).to_numpy()
    assert (df.loc[held, f"mode:{TAG}"] == "hold").all()

    # validation: the same samples for the untracked twin, the Python runtime and the tracked FMU
    res = validate(spec, case["fmu"], work_dir=case["root"] / "validate")
    s = res.series
    vmask = _expected_mask(s["time"].to_numpy())
    vmeas = s[f"measured:{TAG}"].to_numpy()
    v = res.variables[TAG]
    assert v.nrmse_python == pytest.approx(_nrmse(s[f"python:{TAG}"].to_numpy()[vmask], vmeas[vmask]), rel=1e-9)
    assert v.nrmse_untracked == pytest.approx(_nrmse(s[f"untracked:{TAG}"].to_numpy()[vmask], vmeas[vmask]),
                                              rel=1e-9)
    assert v.nrmse_tracked == pytest.approx(_nrmse(s[f"tracked:{TAG}"].to_numpy()[vmask], vmeas[vmask]), rel=1e-9)
    # and the runtime inside validate is the tracking run above
    assert v.nrmse_python == pytest.approx(tr.variables[TAG].nrmse_tracked, rel=1e-9)
