"""Parameters of FMI variability ``fixed`` (issue 30, item 1): changed between steps where FMI allows it.

Independent references: the Modelica Association's Reference FMUs (C sources in
``../shared/reference-fmus``, built here once per session for FMI 2 and FMI 3) against the
closed-form solution of ``Dahlquist`` (``x' = -k x``) and scipy's integration of ``VanDerPol``
(``x0' = x1``, ``x1' = mu (1 - x0^2) x1 - x0``) with the parameter switched mid-run; and a CasADi
twin whose ``k`` is declared ``fixed`` tracked and paired like the same twin with ``k`` tunable.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from _fixtures_casadi import rewrite_model_description
from _fixtures_tracking import make_case, make_first_order_fmu
from trackingbox.analysis.pair_stage import PairSettings, pair
from trackingbox.errors import AnalysisError, FMUError, SpecError
from trackingbox.fmu import FMUModel, read_info
from trackingbox.spec import load_spec
from trackingbox.testing.reference_fmus import build_reference_fmus, default_sources
from trackingbox.tracking.runtime import track

pytestmark = pytest.mark.compile


@pytest.fixture(scope="session")
def reference_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[int, dict[str, Path]]:
    """``{2: {"Dahlquist": ..., "VanDerPol": ...}, 3: {...}}``, built once per session."""
    if not (default_sources() / "CMakeLists.txt").is_file():
        pytest.skip(f"the Reference FMUs' sources are not at {default_sources()} (../shared/reference-fmus)")
    root = tmp_path_factory.mktemp("reference-fmus")
    return {v: build_reference_fmus(root, v) for v in (2, 3)}


def _cs_only(fmu: Path, out: Path) -> Path:
    """A copy of *fmu* whose model description offers co-simulation only (as many exported FMUs do)."""
    out.write_bytes(Path(fmu).read_bytes())

    def drop_me(xml: str) -> str:
        start = xml.index("<ModelExchange")
        end = xml.find("</ModelExchange>", start)
        end = xml.index("/>", start) + 2 if end < 0 else end + len("</ModelExchange>")
        return xml[:start] + xml[end:]

    return rewrite_model_description(out, drop_me)


@pytest.mark.parametrize("version", [2, 3])
def test_reference_fmus_declare_their_parameters_fixed(reference_fmus, version):
    info = read_info(reference_fmus[version]["Dahlquist"])
    assert info.variable("k").variability == "fixed"
    assert read_info(reference_fmus[version]["VanDerPol"]).variable("mu").variability == "fixed"
    assert {"ModelExchange", "CoSimulation"} <= set(info.interfaces)


@pytest.mark.parametrize("version", [2, 3])
def test_dahlquist_k_changes_mid_run_as_the_closed_form_says(reference_fmus, version):
    with FMUModel(reference_fmus[version]["Dahlquist"], tolerance=1e-10) as m:
        st = m.stepper(start_time=0.0, parameters={"k": 1.0})
        ts, xs = [0.0], [float(st.get(["x"])[0])]
        for t in np.arange(0.1, 3.0001, 0.1):
            if abs(t - 1.0) < 1e-9:
                pass
            if abs(t - 1.1) < 1e-9:
                st.set({"k": 2.5})  # fixed: a re-initialisation at t = 1 that keeps x
            if abs(t - 2.1) < 1e-9:
                st.set({"k": 0.5})
            st.step(float(t))
            ts.append(float(t))
            xs.append(float(st.get(["x"])[0]))
        assert st.reinitializations == 2
        assert float(st.get(["k"])[0]) == 0.5
    t = np.array(ts)
    # x(t) = exp(-k1 min(t,1)) exp(-k2 clip(t-1, 0, 1)) exp(-k3 max(t-2, 0)), x(0) = 1
    exact = np.exp(-1.0 * np.minimum(t, 1.0) - 2.5 * np.clip(t - 1.0, 0.0, 1.0) - 0.5 * np.maximum(t - 2.0, 0.0))
    np.testing.assert_allclose(xs, exact, rtol=2e-6)


@pytest.mark.parametrize("version", [2, 3])
def test_van_der_pol_mu_changes_mid_run_as_scipy_integrates_it(reference_fmus, version):
    def rhs(mu):
        return lambda _t, x: [x[1], mu * (1.0 - x[0] ** 2) * x[1] - x[0]]

    first = solve_ivp(rhs(1.0), (0.0, 2.0), [2.0, 0.0], rtol=1e-11, atol=1e-12, dense_output=True)
    second = solve_ivp(rhs(3.0), (2.0, 5.0), first.y[:, -1], rtol=1e-11, atol=1e-12, dense_output=True)
    with FMUModel(reference_fmus[version]["VanDerPol"], tolerance=1e-9) as m:
        st = m.stepper(start_time=0.0, parameters={"mu": 1.0})
        got = []
        for t in np.arange(0.25, 5.0001, 0.25):
            if abs(t - 2.25) < 1e-9:
                st.set({"mu": 3.0})
            st.step(float(t))
            got.append((float(t), *st.get(["x0", "x1"])))
    for t, x0, x1 in got:
        ref = first.sol(t) if t <= 2.0 else second.sol(t)
        assert x0 == pytest.approx(ref[0], abs=2e-5), t
        assert x1 == pytest.approx(ref[1], abs=5e-5), t


@pytest.mark.parametrize("version", [2, 3])
def test_co_simulation_only_fmu_refuses_a_fixed_parameter_saying_what_to_do(reference_fmus, version, tmp_path):
    cs = _cs_only(reference_fmus[version]["Dahlquist"], tmp_path / "Dahlquist_cs.fmu")
    assert read_info(cs).interfaces == ("CoSimulation",)
    with FMUModel(cs) as m:
        st = m.stepper(start_time=0.0, parameters={"k": 2.0})  # before initialisation: allowed
        st.step(1.0)
        # its own explicit Euler solver, step 0.1 s: x(1) = (1 - 2 * 0.1)^10
        assert float(st.get(["x"])[0]) == pytest.approx(0.8 ** 10, rel=1e-9)
        with pytest.raises(FMUError) as err:
            st.set({"k": 1.0})
    text = str(err.value)
    assert "\n" not in text
    assert "'k'" in text and "fixed" in text and "co-simulation" in text
    assert "model exchange" in text and "--backend embedded" in text


@pytest.mark.long
def test_pair_and_track_on_a_fixed_parameter_match_the_tunable_twin(tmp_path_factory):
    """The same CasADi twin, ``k`` tunable and ``k`` declared fixed: the step tests' gains and the
    tracked trajectory agree (the fixed one re-initialises at each change and keeps the state)."""
    results = {}
    for variability in ("tunable", "fixed"):
        fmu = make_first_order_fmu(tmp_path_factory.mktemp(f"hx1-{variability}"), variability)
        assert read_info(fmu).variable("k").variability == variability
        spec_path = make_case(fmu, tmp_path_factory.mktemp(f"case-{variability}"))
        spec = load_spec(spec_path)
        paired = pair(spec, PairSettings(data_checks=False, second_point="none"))
        run = track(spec, out_dir=tmp_path_factory.mktemp(f"track-{variability}"))
        results[variability] = (paired, run, pd.read_csv(run.csv))
    (pa, ra, da), (pb, rb, db) = results["tunable"], results["fixed"]
    np.testing.assert_allclose(pb.steptest.gains, pa.steptest.gains, rtol=1e-4)
    assert [(p.variable, p.parameter) for p in pb.pairing.pairs] == [("TI", "k")]
    # the gain of the twin at its operating point: -u tau / (1 + k tau)^2 with k = 0.003, u = 50 (the step
    # tests take secants over finite steps of k, which are within 10 % of the derivative here)
    assert pb.steptest.gains[0, 0] == pytest.approx(-50.0 * 100.0 / (1.0 + 0.3) ** 2, rel=0.1)
    assert rb.complete and ra.complete
    np.testing.assert_allclose(db["parameter:k"], da["parameter:k"], rtol=1e-3, atol=1e-6)
    np.testing.assert_allclose(db["tracked:TI"], da["tracked:TI"], atol=2e-3)
    assert rb.parameters["k"].final == pytest.approx(0.004, rel=0.01)
    assert rb.variables["TI"].nrmse_tracked < 0.3 * rb.variables["TI"].nrmse_untracked


def test_pair_and_track_refuse_a_fixed_parameter_of_a_co_simulation_only_twin(tmp_path, reference_fmus):
    """Dahlquist offered as co-simulation only, ``k`` a candidate: both stages refuse before running,
    in one line that says what to do."""
    _cs_only(reference_fmus[2]["Dahlquist"], tmp_path / "twin.fmu")
    t = np.arange(0.0, 20.01, 0.1)
    pd.DataFrame({"time": t, "X": np.exp(-0.5 * t)}).to_csv(tmp_path / "measurements.csv", index=False)
    (tmp_path / "spec.toml").write_text(
        'twin = "twin.fmu"\nmeasurements = "measurements.csv"\nsample_time = 0.1\n\n[outputs]\n"X" = "x"\n\n'
        '[[parameters]]\nname = "k"\nstart = 1.0\nmin = 0.1\nmax = 2.0\n\n'
        "[windows]\ntraining = [0.0, 10.0]\nvalidation = [10.0, 20.0]\n\n"
        '[[pairs]]\nvariable = "X"\nparameter = "k"\ngain = -0.1\ntime_constant = 1.0\n', encoding="utf-8")
    spec = load_spec(tmp_path / "spec.toml")
    with pytest.raises(AnalysisError) as err:
        pair(spec, PairSettings(data_checks=False, second_point="none"))
    assert "co-simulation" in str(err.value) and "--backend embedded" in str(err.value)
    with pytest.raises(SpecError) as err2:
        track(spec, out_dir=tmp_path / "track")
    assert "co-simulation" in str(err2.value) and "\n" not in str(err2.value)
    assert not (tmp_path / "track").exists() or not any((tmp_path / "track").iterdir())  # nothing written
