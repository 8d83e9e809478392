"""Every bench model compiles with the embedded path, passes fmpy's validation,
and agrees with rumoca's own simulation of the same source.

Two independent integrators: the FMU runs under fmpy's CVode, rumoca under its
own solver. rumoca cannot drive time-varying inputs, so each bench model has
wrappers in ``Benches/<Bench>/Validation`` that bind its inputs to functions of
time; those are what is compared (every variable both report, within 0.1 % of
its range over the run).
"""
from __future__ import annotations

import fmpy
import numpy as np
import pytest
import rumoca
from fmpy.validation import validate_fmu

from _fixtures_benches import bench_models, validation_models
from trackingbox.compiler import library_path

pytestmark = pytest.mark.compile

def test_every_bench_has_plant_twin_and_wrappers():
    models = bench_models()
    benches = {m.split(".")[2] for m in models}
    assert {"HeatExchanger"} <= benches
    for bench in benches:
        assert f"TrackingBox.Benches.{bench}.Plant" in models
        assert f"TrackingBox.Benches.{bench}.Twin" in models
        wrappers = [m for m in validation_models() if m.split(".")[2] == bench]
        assert len(wrappers) >= 2, f"{bench}: a validation wrapper per model"


@pytest.mark.parametrize("model", bench_models())
def test_bench_model_compiles_and_validates(fmu_cache, model):
    fmu = fmu_cache(model)
    assert validate_fmu(str(fmu)) == []
    md = fmpy.read_model_description(str(fmu))
    assert md.fmiVersion == "3.0" and md.modelExchange is not None
    assert [v for v in md.modelVariables if v.causality == "output"], "bench models expose sensors"


@pytest.mark.parametrize("model", validation_models())
def test_fmu_agrees_with_rumoca(fmu_cache, model):
    fmu = fmu_cache(model)
    md = fmpy.read_model_description(str(fmu))
    stop = float(md.defaultExperiment.stopTime) if md.defaultExperiment and md.defaultExperiment.stopTime else 3600.0
    ref = rumoca.Session().load(str(library_path() / "package.mo"), model=model).simulate(
        (0.0, stop), dt=stop / 2000, config=rumoca.SimConfig(rtol=1e-8, atol=1e-8)
    )
    ref_names = set(ref.names)
    names = sorted(
        v.name for v in md.modelVariables
        if v.name in ref_names and v.causality != "parameter" and v.variability == "continuous"
    )
    assert names, "no common variables to compare"
    out = fmpy.simulate_fmu(str(fmu), stop_time=stop, output_interval=stop / 400, output=names,
                            relative_tolerance=1e-8)
    t_ref = np.asarray(ref.time)
    worst = []
    for name in names:
        r = np.interp(out["time"], t_ref, np.asarray(ref[name], dtype=float))
        span = max(np.ptp(r), 1e-6 * max(1.0, float(np.max(np.abs(r)))))
        err = float(np.max(np.abs(out[name] - r)))
        if err > 1e-3 * span:
            worst.append((name, err, span))
    assert not worst, f"{len(worst)} of {len(names)} variables differ by more than 0.1 % of their range: {worst[:5]}"
