"""Tracking with the controllers inside the integrated system (``track(..., controllers="continuous")``).

The reference is independent of the runtime: scipy's ``solve_ivp`` (Radau, tight
tolerances) integrates the closed loop written out here from the equations of the
``Loop`` twin below (a heater ``C dT/dt = Qin - kht A (T - Tc)`` whose exchanger offers
``use_kht_in``, and a tank ``rho area dL/dt = m_in + m_corr - kOut L`` whose correction
is a top-level input, as on the heat-production bench) and of the compiled box's
blocks (``Blocks.ParameterController``: ``e = 100 (u_s - u_m)/span``,
``der(eMem) = (e - eMem)/Te``, ``der(u) = d kp (e/Ti + (e - eMem)/Te)`` clamped and
held, ``kht = pMin + u/100 (pMax - pMin)``; ``Blocks.StateCompensation``:
``der(m) = k (e - eMem)/Te``), with the measurements interpolated linearly between
samples, sample by sample. On the heat-exchanger bench, the mode is compared with
the compiled TrackingBox itself (the reference for this mode) and with the discrete
path.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from trackingbox.compiler import compile_model
from trackingbox.spec import load_spec
from trackingbox.tracking.runtime import track

from _fixtures_generate import BENCH_PAIRS, MINI, box_against_runtime, write_case
from _fixtures_tracking import native_unavailable

pytestmark = pytest.mark.skipif(native_unavailable() is not None, reason=str(native_unavailable()))

C, A, TC = 4.0e5, 10.0, 300.0
RHO, AREA, KOUT, M_IN = 1000.0, 2.0, 2.0, 2.0
TS, HOLD_UNTIL, HOURS = 10.0, 300.0, 2.0

#: Mini's exchanger, and a twin with a tank whose correction flow is a top-level input
LOOP = MINI.replace("package Mini", "package Loop").replace("end Mini;", "").split("  model Twin")[0] + f'''
  model Twin "Heater and tank twin"
    input Real Qin(start = 50000.0) "Heater power (W)";
    input Real m_flow_corr(start = 0.0) "Correction flow into the tank (kg/s)";
    output Real ThOut "Hot temperature (K)";
    output Real LI_100 "Tank level (m)";
    Exchanger hx(kht = 1000.0);
    Real level(start = 1.0, fixed = true) "Level (m)";
  equation
    hx.Qin = Qin;
    hx.Tc = {TC!r};
    ThOut = hx.T;
    {RHO!r}*{AREA!r}*der(level) = {M_IN!r} + m_flow_corr - {KOUT!r}*level;
    LI_100 = level;
  end Twin;
end Loop;
'''

SPEC = f'''twin = "twin.fmu"
measurements = "measurements.csv"
sample_time = {TS!r}

[source]
path = "Loop"
model = "Loop.Twin"

[inputs]
"QI-100" = "Qin"

[outputs]
"TI-102" = "ThOut"
"LI-100" = "LI_100"

[[parameters]]
name = "hx.kht"
start = 1000.0
min = 800.0
max = 1200.0

[windows]
training = [0.0, 3600.0]
validation = [3600.0, 7200.0]

[[pairs]]
variable = "TI-102"
parameter = "hx.kht"
gain = -0.005
time_constant = 40.0
kp = 0.5
ti = 60.0

[[states]]
tag = "LI-100"
variable = "LI_100"
correction = "m_flow_corr"
gain = 5.0

[tracking]
hold_until = {HOLD_UNTIL!r}
'''


def _measurements(grid: np.ndarray, missing: slice | None = None) -> pd.DataFrame:
    rng = np.random.default_rng(7)
    qin = 50000.0 + 6000.0 * np.sin(grid / 900.0)
    kht_plant = 950.0 + 150.0 * np.sin(grid / 1500.0)  # inside the bounds 800..1200 but for its peaks
    temp = TC + qin / (A * kht_plant) + rng.normal(0.0, 0.02, grid.size)
    level = 1.0 + 0.04 * np.sin(grid / 800.0) + rng.normal(0.0, 0.002, grid.size)
    if missing is not None:
        temp[missing] = np.nan
    return pd.DataFrame({"time": grid, "QI-100": qin, "TI-102": temp, "LI-100": level})


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory):
    """The Loop case: a pair TI-102 -> hx.kht and the compensation of LI-100 by m_flow_corr."""
    root = tmp_path_factory.mktemp("continuous")
    (root / "case" / "Loop").mkdir(parents=True)
    (root / "case" / "Loop" / "package.mo").write_text(LOOP)
    spec_path = root / "case" / "spec.toml"
    spec_path.write_text(SPEC)
    grid = np.arange(0.0, HOURS * 3600.0 + 1e-9, TS)
    _measurements(grid).to_csv(root / "case" / "measurements.csv", index=False)
    compile_model(root / "case" / "Loop", "Loop.Twin", backend="embedded", output=root / "case" / "twin.fmu")
    from trackingbox.generate.inputs_twin import inputs_twin

    spec = load_spec(spec_path)
    return {"root": root, "spec": spec, "grid": grid, "inputs_twin": inputs_twin(spec, cache=root / "cache")}


def _reference(spec, grid: np.ndarray, data: pd.DataFrame) -> dict[str, np.ndarray]:
    """The closed loop integrated by solve_ivp, sample by sample: the values at every sample."""
    from trackingbox.tracking.controllers import MEMORY_FRACTION
    from trackingbox.tracking.tuning import pair_settings

    pair = spec.pairs[0]
    p = spec.parameter(pair.parameter)
    s = pair_settings(pair, float(p.min), float(p.max), ts=TS, where="test")
    gain, ti, span, te = s.direction * s.kp, s.ti, s.scaling.span, MEMORY_FRACTION * TS
    k_comp = float(spec.states[0].gain)
    pmin, pmax = float(p.min), float(p.max)
    meas_t, meas_l, qin = (data[c].to_numpy() for c in ("TI-102", "LI-100", "QI-100"))

    def rhs(t: float, z: np.ndarray, hold: bool) -> np.ndarray:
        temp, level, mem_p, u, mem_s, m = z
        kht = pmin + min(max(u, 0.0), 100.0) / 100.0 * (pmax - pmin)
        q = np.interp(t, grid, qin)
        e = 100.0 * (np.interp(t, grid, meas_t) - temp) / span
        rate = gain * (e / ti + (e - mem_p) / te)
        du = 0.0 if hold or (u >= 100.0 and rate > 0.0) or (u <= 0.0 and rate < 0.0) else rate
        e_s = np.interp(t, grid, meas_l) - level
        return np.array([(q - kht * A * (temp - TC)) / C,
                         (M_IN + m - KOUT * level) / (RHO * AREA),
                         (e - mem_p) / te, du,
                         (e_s - mem_s) / te, k_comp * (e_s - mem_s) / te])

    # the twin's start; the error memories at 0 and the correction at 0, as the blocks start
    z = np.array([350.0, 1.0, 0.0, 100.0 * (float(p.start) - pmin) / (pmax - pmin), 0.0, 0.0])
    out = np.empty((grid.size, z.size))
    out[0] = z
    for k in range(grid.size - 1):
        hold = grid[k] < HOLD_UNTIL - 1e-9
        sol = solve_ivp(rhs, (grid[k], grid[k + 1]), z, method="Radau", rtol=1e-10, atol=1e-10, args=(hold,))
        z = sol.y[:, -1]
        out[k + 1] = z
    kht = pmin + np.clip(out[:, 3], 0.0, 100.0) / 100.0 * (pmax - pmin)
    return {"tracked:TI-102": out[:, 0], "tracked:LI-100": out[:, 1], "parameter:hx.kht": kht,
            "correction:m_flow_corr": out[:, 5]}


def test_continuous_mode_follows_solve_ivp_of_the_closed_loop(case, tmp_path: Path) -> None:
    spec, grid = case["spec"], case["grid"]
    data = _measurements(grid)
    ref = _reference(spec, grid, data)
    result = track(spec, out_dir=tmp_path / "run", checkpoint_every=10**9, controllers="continuous",
                   inputs_twin=case["inputs_twin"], tolerance=1e-10)
    got = pd.read_csv(result.csv)
    assert result.complete and len(got) == grid.size
    # the parameter left its start (the loop did something) and the hold kept it there until HOLD_UNTIL
    kht = got["parameter:hx.kht"].to_numpy()
    assert np.all(kht[grid < HOLD_UNTIL] == 1000.0)
    assert np.ptp(kht) > 200.0 and np.mean((kht > 800.0) & (kht < 1200.0)) > 0.5  # moves, mostly unclamped
    for column, expected in ref.items():
        span = float(np.ptp(expected)) or 1.0
        worst = float(np.max(np.abs(got[column].to_numpy() - expected))) / span
        assert worst <= 1e-6, (column, worst)


def test_continuous_mode_holds_a_pair_whose_tag_is_missing(case, tmp_path: Path) -> None:
    # TI-102 missing for 2 minutes in the middle: those rows go through the discrete path (the
    # "missing" and "resumed" events), the parameter stays where it was, the run goes on in C after
    spec, grid = case["spec"], case["grid"]
    gap = slice(400, 412)
    case_dir = tmp_path / "case"
    case_dir.mkdir()
    _measurements(grid, missing=gap).to_csv(case_dir / "measurements.csv", index=False)
    text = spec.path.read_text().replace('path = "Loop"', f'path = "{spec.path.parent / "Loop"}"')
    (case_dir / "spec.toml").write_text(text.replace('twin = "twin.fmu"', f'twin = "{spec.path.parent / "twin.fmu"}"'))
    spec2 = load_spec(case_dir / "spec.toml")
    result = track(spec2, out_dir=tmp_path / "run", checkpoint_every=10**9, controllers="continuous",
                   inputs_twin=case["inputs_twin"])
    got = pd.read_csv(result.csv)
    kinds = [e.kind for e in result.events]
    assert "missing" in kinds and "resumed" in kinds
    assert (got["mode:TI-102"].iloc[gap] == "hold").all()
    kht = got["parameter:hx.kht"].to_numpy()
    assert np.ptp(kht[gap.start: gap.stop]) == 0.0
    assert kht[gap.stop + 30] != kht[gap.stop]  # tracking again after the gap
    assert np.isfinite(got["tracked:TI-102"]).all()


def test_continuous_mode_resumes_to_the_same_bytes(case, tmp_path: Path) -> None:
    spec = case["spec"]
    it = case["inputs_twin"]
    whole = track(spec, out_dir=tmp_path / "whole", checkpoint_every=100, controllers="continuous", inputs_twin=it)
    track(spec, out_dir=tmp_path / "parts", checkpoint_every=100, controllers="continuous", inputs_twin=it,
          max_steps=200)
    parts = track(spec, out_dir=tmp_path / "parts", checkpoint_every=100, controllers="continuous", inputs_twin=it,
                  resume=True)
    assert parts.complete
    assert (tmp_path / "parts" / "tracking.csv").read_bytes() == whole.csv.read_bytes()


def test_a_checkpoint_of_the_other_mode_is_refused(case, tmp_path: Path) -> None:
    from trackingbox.errors import SpecError

    spec = case["spec"]
    track(spec, out_dir=tmp_path / "run", checkpoint_every=100, max_steps=150)
    with pytest.raises(SpecError, match="controllers='discrete'"):
        track(spec, out_dir=tmp_path / "run", checkpoint_every=100, controllers="continuous",
              inputs_twin=case["inputs_twin"], resume=True)


def test_continuous_mode_needs_the_source(tmp_path: Path) -> None:
    from trackingbox.errors import SpecError
    from trackingbox.generate.inputs_twin import inputs_twin

    spec_path = write_case(tmp_path / "case", source=False)
    with pytest.raises(SpecError, match="no \\[source\\]"):
        inputs_twin(load_spec(spec_path, check_files=False))


@pytest.mark.compile
def test_continuous_mode_agrees_with_the_compiled_box_on_the_heat_exchanger(fmu_cache, tmp_path: Path) -> None:
    """The heat-exchanger bench (3 h, seed 1, the pair of _fixtures_generate's BENCH_PAIRS), default tolerances.

    Measured: the continuous mode is within 2.8e-5 of the parameter's range of the box (95th
    percentile 1.4e-5), the discrete path 2.4e-4 (8.6e-5); at rtol 1e-10 for both (runtime and box)
    the continuous mode is within 1.3e-8 of the box, the discrete path 6e-5 (its discretisation).
    """
    from trackingbox.benches import make_bench
    from trackingbox.generate.generator import compile_generated, generate

    model = "TrackingBox.Benches.HeatExchanger"
    make_bench("heat-exchanger", tmp_path / "case", seed=1, hours=3.0,
               plant_fmu=fmu_cache(f"{model}.Plant"), twin_fmu=fmu_cache(f"{model}.Twin"))
    spec_path = tmp_path / "case" / "spec.toml"
    spec_path.write_text(spec_path.read_text().replace("[tracking]", BENCH_PAIRS["heat-exchanger"].lstrip()
                                                       + "\n[tracking]"))
    spec = load_spec(spec_path)
    box = compile_generated(generate(spec, tmp_path / "generated"), backend="embedded").fmu
    runs = {mode: track(spec, out_dir=tmp_path / mode, window="validation", controllers=mode)
            for mode in ("discrete", "continuous")}
    agreement = {mode: box_against_runtime(spec, box, r.csv)["hx.kht"] for mode, r in runs.items()}
    worst_c, p95_c = agreement["continuous"]
    worst_d, _ = agreement["discrete"]
    assert worst_c <= 1e-4 and p95_c <= 5e-5, agreement
    assert worst_c <= worst_d, agreement  # at least as accurate against the box as the discrete path
    a, b = (pd.read_csv(r.csv)["parameter:hx.kht"].to_numpy() for r in runs.values())
    assert float(np.max(np.abs(a - b))) / 1000.0 <= 5e-4


def test_cli_runs_the_continuous_mode_and_refuses_it_live(case, tmp_path: Path, monkeypatch, capsys) -> None:
    import json

    from trackingbox.cli import main

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))  # the inputs twin is compiled into it
    spec = case["spec"]
    assert main(["track", str(spec.path), "--controllers", "continuous", "--out", str(tmp_path / "run"),
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["variables"]["TI-102"]["nrmse_tracked"] < doc["variables"]["TI-102"]["nrmse_untracked"]
    assert len(pd.read_csv(tmp_path / "run" / "tracking.csv")) == case["grid"].size
    assert list((tmp_path / "xdg" / "trackingbox" / "inputs-twins").glob("TwinInputs-*.fmu"))
    code = main(["track", str(spec.path), "--controllers", "continuous", "--live", "opc.tcp://127.0.0.1:4840",
                 "--out", str(tmp_path / "live")])
    assert code == 2
    assert "not available with --live" in capsys.readouterr().err
