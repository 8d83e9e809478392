"""Exact sensitivities from the FMU's directional derivatives, and their use in the estimation's refinement.

Independent expectations: central finite differences of the same twin at a much
tighter integrator tolerance (their error budget is argued at each test), the
model description's own flags, and the true parameter of synthetic data.
"""
from __future__ import annotations

import math
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from _fixtures_estimation import plant_data, write_case
from trackingbox import estimation
from trackingbox.estimation import objective as objective_module
from trackingbox.errors import EstimationError
from trackingbox.estimation import Objective, Problem, WindowData, estimate
from trackingbox.fmu import FMUModel, directional_derivatives_reason, read_info
from trackingbox.sensitivity import simulate_sensitivities, support
from trackingbox.spec import load_spec

pytestmark = pytest.mark.compile

TWIN = "TrackingBox.Benches.HeatExchanger.Twin"
OUTPUTS = ["ThOut", "TcOut"]
#: parameters and their bound ranges (the scales the estimation uses)
WRT = {"hx.kht": 1000.0, "hx.A": 2.0}
START = {"hx.kht": 1000.0, "hx.A": 4.2}


def _inputs(t: np.ndarray) -> pd.DataFrame:
    """Bench-like excitation: hot and cold flows with steps and sines, inlet temperatures with slow sines."""
    return pd.DataFrame({
        "time": t,
        "mHot_flow": 1.0 + 0.3 * np.sin(t / 600.0) + 0.2 * (np.sin(t / 1700.0) > 0),
        "ThIn": 363.0 + 4.0 * np.sin(t / 900.0),
        "mCold_flow": 2.0 + 0.4 * np.sin(t / 800.0 + 1.0),
        "TcIn": 283.0 + 2.0 * np.sin(t / 1300.0),
    })


@pytest.fixture(scope="module")
def twin(fmu_cache) -> Path:
    return fmu_cache(TWIN)  # compiled once per session


def test_the_embedded_twin_declares_directional_derivatives(twin: Path) -> None:
    # the embedded path's FMI 3 FMUs say providesDirectionalDerivatives="true" (fmpy 0.3.32 does not read it)
    with zipfile.ZipFile(twin) as zf:
        xml = zf.read("modelDescription.xml").decode()
    assert 'providesDirectionalDerivatives="true"' in xml
    assert directional_derivatives_reason(read_info(twin)) is None


def test_output_sensitivities_match_central_differences(twin: Path) -> None:
    """dy/dp of both outlet temperatures w.r.t. kht and A over 2 h, against central differences.

    Reference: central differences with a step of 1 % of each range (10 W/(m2 K), 0.02 m2) at
    rtol 1e-10. Their error: truncation O(h^2), measured as 4e-5 of max|dy/dp| at h = 10 for
    kht, plus integrator noise ~1e-9 K / 2h, negligible. The exact run integrates at the
    estimation's rtol 1e-6 with the sensitivities' absolute tolerance 100x the states'
    (measured 1.1e-4 of max|dy/dp| on the bench's 8 h run). Accepted: 1e-3 of max|dy/dp| per
    output and parameter, ten times what both errors together were measured at.
    """
    t = np.arange(0.0, 7200.0 + 5.0, 10.0)
    u = _inputs(t)
    with FMUModel(twin) as model:
        run = simulate_sensitivities(model, wrt=list(WRT), scales=list(WRT.values()), stop_time=7200.0,
                                     output_interval=10.0, inputs=u, parameters=START, outputs=OUTPUTS)
    assert run.time.size == t.size and run.directional_calls > 0
    with FMUModel(twin, tolerance=1e-10) as tight:
        for j, (name, span) in enumerate(WRT.items()):
            h = 0.01 * span
            up = tight.simulate(stop_time=7200.0, output_interval=10.0, inputs=u,
                                parameters={**START, name: START[name] + h}, outputs=OUTPUTS)
            down = tight.simulate(stop_time=7200.0, output_interval=10.0, inputs=u,
                                  parameters={**START, name: START[name] - h}, outputs=OUTPUTS)
            for out in OUTPUTS:
                central = (up[out].to_numpy() - down[out].to_numpy()) / (2 * h)
                exact = run.sensitivities[out][:, j]
                size = float(np.max(np.abs(central)))
                assert size > 0, f"d{out}/d{name} vanishes: the case does not excite it"
                assert np.max(np.abs(exact - central)) <= 1e-3 * size, (out, name)
    # the twin starts from its own start values, which no parameter sets: no sensitivity at t = 0
    assert np.all(run.sensitivities["ThOut"][0] == 0.0)


def test_refinement_jacobian_matches_central_differences(twin: Path) -> None:
    """The estimation's exact Jacobian of its weighted residuals against central differences of its residuals.

    Same runs as the estimation (10 min held pre-run, then 1 h), both at the default rtol 1e-6.
    The central difference takes 5 % of each range: its truncation error was measured at
    5e-4 of max|dy/dp| for kht at that step; the integrator's noise in a residual (about 1e-5 K
    here) divided by 2h is below 1e-3 of it. Accepted: 1e-2 of each column's largest entry.
    """
    t = np.arange(0.0, 3600.0 + 5.0, 10.0)
    u = _inputs(t)
    problem = Problem(twin=twin, names=tuple(WRT), start=np.array(list(START.values())),
                      lower=np.array([500.0, 3.2]), upper=np.array([1500.0, 5.2]), fixed={},
                      outputs={"TI-102": "ThOut", "TI-202": "TcOut"}, sample_time=10.0, warmup=600.0)
    with FMUModel(twin) as model:  # "measurements": the twin at other values, offset so residuals are not zero
        truth = model.simulate(start_time=-600.0, stop_time=3600.0, output_interval=10.0,
                               inputs=pd.concat([u.iloc[:1].assign(time=-600.0), u]),
                               parameters={"hx.kht": 900.0, "hx.A": 4.0}, outputs=OUTPUTS)
    keep = truth["time"].to_numpy() >= 0.0
    window = WindowData("training", 0.0, 3600.0, t, {k: u[k].to_numpy() for k in u if k != "time"},
                        {"TI-102": truth["ThOut"].to_numpy()[keep] + 0.3,
                         "TI-202": truth["TcOut"].to_numpy()[keep] - 0.2})
    objective = Objective(problem, window)
    x = problem.start
    try:
        r, jac = objective_module.residuals_and_jacobian(objective, x)
        # the two runs take different steps (the sensitivities are error-controlled too): their outputs
        # differ by the integrator's error, about rtol * |y| = 1e-6 * 350 K, i.e. ~1e-3 of these
        # residuals (offsets of 0.2-0.3 K); measured 2e-4
        assert np.allclose(r, objective.residuals(x), rtol=0.0, atol=1e-3 * np.max(np.abs(r)))
        for j in range(len(x)):
            h = np.zeros_like(x)
            h[j] = 0.05 * (problem.upper[j] - problem.lower[j])
            central = (objective.residuals(x + h) - objective.residuals(x - h)) / (2 * h[j])
            assert np.max(np.abs(jac[:, j] - central)) <= 1e-2 * np.max(np.abs(central)), problem.names[j]
    finally:
        estimation.close_models()


# --------------------------------------------------------------------------- in estimate()


@pytest.fixture(scope="module")
def case(hx_fmu: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The first-order heat exchanger of the estimation tests (kht = 900 in the data), 4 h, noise 0.1 K.

    Runs start from the FMU's own initial state (``[data] initial = "model"``): the sensitivity equations
    start at zero there (from a steady state, which moves with the parameters, ``exact`` is refused);
    the training window starts after an hour of history (the twin's time constant is about a minute),
    so the warm-up through it forgets the twin's 20 degC start.
    """
    return write_case(tmp_path_factory.mktemp("sens-case"), hx_fmu, plant_data(hx_fmu, 900.0, noise=0.1, seed=1),
                      training=(3600.0, 9000.0), validation=(9000.0, 14400.0), initial="model")


def _without_directional_derivatives(src: Path, dst: Path) -> Path:
    """A copy of *src* whose model description does not declare directional (nor adjoint) derivatives."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                assert 'providesDirectionalDerivatives="true"' in text
                text = text.replace('providesDirectionalDerivatives="true"', 'providesDirectionalDerivatives="false"')
                data = text.replace('providesAdjointDerivatives="true"', 'providesAdjointDerivatives="false"').encode()
            zout.writestr(item, data)
    return dst


def test_exact_and_fd_refinements_reach_the_same_estimate(case: Path) -> None:
    spec = load_spec(case)
    exact = estimate(spec, seed=0, maxiter=0, jacobian="exact")
    fd = estimate(spec, seed=0, maxiter=0, jacobian="fd")
    assert exact.refinement["jacobian"] == "exact" and exact.refinement["reason"] == ""
    assert exact.to_json()["refinement"]["jacobian"] == "exact"
    assert fd.refinement["jacobian"] == "fd" and fd.refinement["requested"] == "fd"
    # both minimise the same cost from the same start: same point to well within the noise's
    # standard error of kht (about 1.5 W/(m2 K) for this case, see test_estimation)
    assert abs(exact.parameters["kht"] - fd.parameters["kht"]) <= 0.3
    assert abs(exact.parameters["kht"] - 900.0) <= 10.0
    assert math.isclose(exact.training_nrmse["TI-1"], fd.training_nrmse["TI-1"], rel_tol=1e-3)
    # one run gives residuals and Jacobian: fewer runs than 1 + n per iteration
    assert exact.refinement["runs"] < fd.refinement["runs"]


def test_auto_takes_fd_where_the_runs_are_native_and_exact_on_the_python_path(case: Path, monkeypatch) -> None:
    from trackingbox.native import native_reason
    from trackingbox.fmu import FMUModel

    spec = load_spec(case)
    with FMUModel(spec.twin) as model:
        if native_reason(model) is not None:
            pytest.skip(f"no native stepper here: {native_reason(model)}")
    native = estimate(spec, seed=0, maxiter=0, jacobian="auto")
    assert native.refinement["jacobian"] == "fd"
    assert "runs on the native stepper" in native.refinement["reason"]
    # "prefer-exact" (diagnosis's setting) keeps the sensitivity equations on a native twin
    prefer = estimate(spec, seed=0, maxiter=0, jacobian="prefer-exact")
    assert prefer.refinement["jacobian"] == "exact" and prefer.refinement["reason"] == ""
    monkeypatch.setenv("TRACKINGBOX_NATIVE", "0")
    python = estimate(spec, seed=0, maxiter=0, jacobian="auto")
    assert python.refinement["jacobian"] == "exact" and python.refinement["reason"] == ""
    assert abs(native.parameters["kht"] - python.parameters["kht"]) <= 0.3


def test_twin_without_directional_derivatives_falls_back_to_fd(case: Path, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("TRACKINGBOX_NATIVE", "0")  # where the runs are native, "auto" takes fd anyway
    directory = tmp_path / "case"
    shutil.copytree(case.parent, directory)
    _without_directional_derivatives(case.parent / "hx1.fmu", directory / "hx1.fmu")
    spec = load_spec(directory / "spec.toml")
    result = estimate(spec, seed=0, maxiter=0, jacobian="auto")
    assert result.refinement["jacobian"] == "fd"
    assert "does not declare providesDirectionalDerivatives" in result.refinement["reason"]
    assert result.to_json()["refinement"]["reason"] == result.refinement["reason"]
    assert abs(result.parameters["kht"] - 900.0) <= 10.0
    prefer = estimate(spec, seed=0, maxiter=0, jacobian="prefer-exact")
    assert prefer.refinement["jacobian"] == "fd" and prefer.refinement["reason"] == result.refinement["reason"]
    with pytest.raises(EstimationError, match="jacobian = 'exact' is not possible: hx1.fmu does not declare"):
        estimate(spec, seed=0, maxiter=0, jacobian="exact")
    with pytest.raises(EstimationError, match="jacobian must be one of auto, exact, fd"):
        estimate(spec, seed=0, maxiter=0, jacobian="analytic")


def test_support_checks_parameters_as_knowns(hx_fmu: Path) -> None:
    # the CasADi FMU's d(der T)/dkht against a central difference at the start point:
    # der T = (m cp (Tin - T) - kht A (T - Tamb)) / C, so d/dkht = -A (T - Tamb) / C, nonzero at T = 20 degC
    with FMUModel(hx_fmu) as model:
        found = support(model, ["kht"], [1000.0], parameters={"A": 2.0})
    assert found.exact, found.reason
    assert found.mismatch is not None and found.mismatch["kht"] <= 1e-6
