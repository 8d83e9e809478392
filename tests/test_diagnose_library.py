"""The effect library of ``diagnose``: entries, targets, patches, hooks.

Expectations are hand-derived: which components of the bench twins each entry
may act on (read from the Modelica source by eye), and what each effect does
to the simulated twin (a bias of b shifts the reading by b; a drift d gives
d*t/(1 + c*t) from t = 0; a lag follows dy/dt = (x - y)/tau, integrated here with scipy; a leak of
k kg/s lowers the tank's mass rate by k in its balance; a heat loss UA takes
UA*(T - 293.15 K) out of the water; fouling scales kht by 1 - r*t/(1 + c*t)).
One patch per bench carries every built-in effect on every target it finds,
so each bench compiles once.
"""
from __future__ import annotations

import shutil
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.signal import lsim

from trackingbox.compiler import library_path
from trackingbox.diagnose.library import (
    Finding, load_effects, patched_spec, prefix_for, read_effect, render_patch, targets)
from trackingbox.errors import SpecError
from trackingbox.spec import SourceSpec, Spec, check_against_fmu, load_spec

HX = "TrackingBox.Benches.HeatExchanger.Twin"
HP = "TrackingBox.Benches.HeatProduction.Twin"
HP_TAGS = {"LI-200": "LI_200", "TI-100": "TI_100", "TI-300": "TI_300", "FI-100": "FI_100", "PI-100": "PI_100"}


def _spec(tmp: Path, twin_fmu: Path, model: str, outputs: dict[str, str]) -> Spec:
    tmp.mkdir(parents=True, exist_ok=True)
    meas = tmp / "measurements.csv"
    pd.DataFrame({"time": [0.0, 10.0], **{t: [0.0, 0.0] for t in outputs}}).to_csv(meas, index=False)
    return Spec(path=tmp / "spec.toml", twin=Path(twin_fmu), measurements=meas, sample_time=10.0,
                source=SourceSpec(Path(library_path()), model), outputs=dict(outputs))


@pytest.fixture(scope="module")
def hx_spec(fmu_cache, tmp_path_factory):
    return _spec(tmp_path_factory.mktemp("hxspec"), fmu_cache(HX), HX, {"TI-102": "ThOut", "TI-202": "TcOut"})


@pytest.fixture(scope="module")
def hp_spec(fmu_cache, tmp_path_factory):
    return _spec(tmp_path_factory.mktemp("hpspec"), fmu_cache(HP), HP, HP_TAGS)


# --------------------------------------------------------------------------- entries

def test_builtin_entries():
    effects = load_effects()
    assert sorted(effects) == ["bpr-offset", "ds-meter", "entrainment", "fouling", "heat-loss", "leak", "level-density",
                               "sensor-bias", "sensor-drift", "sensor-lag", "shell-heat-loss", "soluble-scale",
                               "steam-vent", "vapour-line"]
    assert {e.kind for e in effects.values()} == {"sensor", "process"}
    assert effects["fouling"].screen == "levelling-ramp" and effects["fouling"].coefficient == "kht"
    assert effects["leak"].hook == "use_leak"
    for e in effects.values():
        assert e.explanation and e.parameters
        for p in e.parameters:
            assert p.min < p.max and p.min <= p.start <= p.max


def _entry(root: Path, name: str, toml: str, template: str = "  parameter Real << prefix >>_k = 1.0;\n") -> Path:
    folder = root / name
    folder.mkdir(parents=True)
    (folder / "effect.toml").write_text(textwrap.dedent(toml))
    (folder / "patch.mo.jinja").write_text(template)
    return folder


GOOD = """\
    id = "{id}"
    explanation = "A user effect."
    kind = "process"
    classes = ["TrackingBox.Fluid.OpenTank"]
    hook = "use_leak"
    [[parameters]]
    name = "k"
    unit = "kg/s"
    start = 0.0
    min = 0.0
    max = 1.0
"""


@pytest.mark.parametrize("text, field", [
    (GOOD.replace('kind = "process"', 'kind = "proces"'), "'kind'"),
    (GOOD.replace('unit = "kg/s"\n', ""), "'unit'"),
    (GOOD.replace("start = 0.0", "start = 2.0"), "'start'"),
    (GOOD.replace('classes = ["TrackingBox.Fluid.OpenTank"]', "classes = []"), "'classes'"),
    (GOOD.replace('hook = "use_leak"', 'hook = "use_leak"\nscreeen = "bias"'), "'screeen'"),
    (GOOD.replace('id = "{id}"', 'id = "other-name"'), "'id'"),
    (GOOD.replace('hook = "use_leak"', 'hook = "use_leak"\nscreen = "levelling-ramp"\ncoefficient = "kht"'),
     "needs exactly two [[parameters]]"),
    (GOOD.replace("max = 1.0", 'max = 1.0\nper = "A"'), "'per_range'"),
    (GOOD.replace("max = 1.0", 'max = 1.0\nper = "A"\nper_range = [0.5, 1.0, 0.0]'), "'per_range'"),
    (GOOD.replace("max = 1.0", 'max = 1.0\nper = "A.b"\nper_range = [0.0, 0.0, 1.0]'), "'per'"),
])
def test_bad_entry_names_file_and_field(tmp_path, text, field):
    folder = _entry(tmp_path, "my-effect", text.replace("{id}", "my-effect"))
    with pytest.raises(SpecError) as err:
        load_effects([tmp_path])
    assert str(folder / "effect.toml") in str(err.value)
    assert field in str(err.value)


def test_bad_template_names_file_and_line(tmp_path):
    folder = _entry(tmp_path, "my-effect", GOOD.replace("{id}", "my-effect"),
                    template="  parameter Real x = 1;\n  << prefix \n")
    with pytest.raises(SpecError, match=r"patch\.mo\.jinja:\d+: template syntax error"):
        read_effect(folder)


def test_user_folder_from_spec(tmp_path):
    _entry(tmp_path / "effects", "pipe-deposit", GOOD.replace("{id}", "pipe-deposit"))
    (tmp_path / "twin.fmu").write_bytes(b"")
    (tmp_path / "m.csv").write_text("time,T\n0,1\n")
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text('twin = "twin.fmu"\nmeasurements = "m.csv"\nsample_time = 10.0\n'
                         '[outputs]\nT = "y"\n[diagnose]\neffects = ["effects"]\n')
    spec = load_spec(spec_file)
    assert spec.diagnose.effects == ((tmp_path / "effects").resolve(),)
    effects = load_effects(spec.diagnose.effects)
    assert "pipe-deposit" in effects and "leak" in effects
    spec_file.write_text(spec_file.read_text().replace('["effects"]', '["nowhere"]'))
    with pytest.raises(SpecError, match=r"effects folder 'nowhere' in \[diagnose\] does not exist"):
        load_spec(spec_file)
    spec_file.write_text(spec_file.read_text().replace('effects = ["nowhere"]', 'effects = "effects"'))
    with pytest.raises(SpecError, match=r"effects in \[diagnose\] must be a list"):
        load_spec(spec_file)


# --------------------------------------------------------------------------- targets

@pytest.mark.compile
def test_targets_on_both_benches(hx_spec, hp_spec):
    effects = load_effects()
    # read from PartialBench / PartialProcess: hx is the one exchanger; HEX300 an exchanger,
    # HU300 a heating unit, T100/T200/T400 open tanks
    assert targets(effects["fouling"], hx_spec) == ["hx"]
    assert targets(effects["heat-loss"], hx_spec) == ["hx"]
    assert targets(effects["leak"], hx_spec) == []
    assert targets(effects["sensor-bias"], hx_spec) == ["TI-102", "TI-202"]
    assert targets(effects["fouling"], hp_spec) == ["HEX300", "HU300"]
    assert targets(effects["heat-loss"], hp_spec) == ["HEX300", "HU300", "T100", "T200", "T400"]
    assert targets(effects["leak"], hp_spec) == ["T100", "T200", "T400"]
    assert targets(effects["sensor-lag"], hp_spec) == list(HP_TAGS)


def test_process_effect_needs_source(tmp_path):
    spec = Spec(path=tmp_path / "s.toml", twin=tmp_path / "t.fmu", measurements=tmp_path / "m.csv",
                sample_time=1.0, outputs={"T": "y"})
    with pytest.raises(SpecError, match=r"has no \[source\]"):
        targets(load_effects()["leak"], spec)


# --------------------------------------------------------------------------- patches

def _all_findings(spec: Spec) -> list[Finding]:
    values = {"sensor-bias": {"b": None}, "sensor-drift": {"d": None}, "sensor-lag": {"tau": 40.0},
              "fouling": {"r": 5e-6, "c": 5e-4}, "heat-loss": {"UA": 200.0}, "leak": {"k": 0.004}}
    found = []
    effects = load_effects()
    units = {"K": (1.5, 5e-5), "m": (0.02, 1e-6), "kg/s": (0.01, 1e-6), "Pa": (3000.0, 0.1)}
    from trackingbox.fmu import read_info
    info = read_info(spec.twin)
    for eid, effect in sorted(effects.items()):
        for target in targets(effect, spec):
            vals = dict(values[eid])
            if effect.kind == "sensor" and None in vals.values():
                unit = info.variable(spec.outputs[target]).unit
                b, d = units[unit]
                vals = {"b": b} if eid == "sensor-bias" else {"d": d, "c": 2e-4}
            found.append(Finding(eid, target, vals))
    return found


@pytest.mark.compile
def test_render_is_deterministic_and_states_the_values(hp_spec):
    findings = _all_findings(hp_spec)
    a = render_patch(hp_spec, findings)
    b = render_patch(hp_spec, list(reversed(findings)))
    assert a.source == b.source
    assert a.model == "TwinDiagnosed"
    assert "extends TrackingBox.Benches.HeatProduction.Twin(" in a.source
    assert "T200(use_heatLoss = true, use_leak = true)" in a.source
    assert "//   leak on T200: leak_T200_k = 0.004 kg/s" in a.source
    assert a.diff.startswith("--- /dev/null\n+++ b/TwinDiagnosed.mo\n@@ -0,0 +1,")
    assert "\n+  extends TrackingBox.Benches.HeatProduction.Twin(" in a.diff
    assert a.outputs["TI-300"] == "sensorBias_TI_300_y" or a.outputs["TI-300"].endswith("_TI_300_y")
    assert {p.name for p in a.parameters} >= {"leak_T200_k", "fouling_HEX300_r", "heatLoss_T100_UA"}


@pytest.mark.compile
def test_render_refuses_bad_findings(hp_spec):
    with pytest.raises(SpecError, match=r"outside its bounds"):
        render_patch(hp_spec, [Finding("leak", "T200", {"k": 0.5})])
    with pytest.raises(SpecError, match=r"unknown effect 'leek'.*did you mean 'leak'"):
        render_patch(hp_spec, [Finding("leek", "T200", {})])
    with pytest.raises(SpecError, match=r"'HU300' is not a component .* the effect applies to"):
        render_patch(hp_spec, [Finding("leak", "HU300", {})])
    with pytest.raises(SpecError, match=r"no parameter 'kk'"):
        render_patch(hp_spec, [Finding("leak", "T200", {"kk": 0.1})])


def _lag(t: np.ndarray, x: np.ndarray, tau: float) -> np.ndarray:
    _, y, _ = lsim(([1.0], [tau, 1.0]), x, t - t[0], X0=[x[0] * tau])
    return y


def _sensor_outputs(findings: list[Finding]) -> list[str]:
    return [f"{prefix_for(f.effect, f.target)}_y" for f in findings if f.effect.startswith("sensor-")]


def _check_sensor_effects(df: pd.DataFrame, patch, spec: Spec, findings: list[Finding]) -> None:
    t = df["time"].to_numpy()
    for f in findings:
        eff = load_effects()[f.effect]
        if eff.kind != "sensor":
            continue
        x = df[spec.outputs[f.target]].to_numpy()
        y = df[f"{prefix_for(f.effect, f.target)}_y"].to_numpy()
        span = max(np.ptp(x), 1e-9)
        if f.effect == "sensor-bias":
            np.testing.assert_allclose(y - x, f.values["b"], atol=1e-9 * max(1.0, abs(x).max()))
        elif f.effect == "sensor-drift":
            # from zero at the first sample (t = 0 on the data's clock), nothing before
            tt = np.maximum(t, 0.0)
            np.testing.assert_allclose(y - x, f.values["d"] * tt / (1 + f.values["c"] * tt),
                                       atol=1e-9 * max(1.0, abs(x).max()))
        else:
            assert np.max(np.abs(y - _lag(t, x, f.values["tau"]))) < 0.02 * span + 1e-6 * abs(x).max()


@pytest.fixture(scope="module")
def hx_patch(hx_spec, tmp_path_factory):
    from trackingbox.diagnose.library import compile_patch

    findings = _all_findings(hx_spec)
    patch = render_patch(hx_spec, findings)
    result = compile_patch(patch, tmp_path_factory.mktemp("hxpatch"))
    return patch, findings, Path(result.fmu)


@pytest.fixture(scope="module")
def hp_patch(hp_spec, tmp_path_factory):
    from trackingbox.diagnose.library import compile_patch

    findings = _all_findings(hp_spec)
    patch = render_patch(hp_spec, findings)
    result = compile_patch(patch, tmp_path_factory.mktemp("hppatch"))
    return patch, findings, Path(result.fmu)


@pytest.mark.compile
def test_hx_patch_effects_act_as_explained(hx_spec, hx_patch):
    from trackingbox.fmu import FMUModel

    patch, findings, fmu = hx_patch
    names = ["ThIn", "ThOut", "TcOut", "hx.kht_internal", "hx.Q_total", "hx.Q_flow_loss_internal",
             *[f"hx.T1[{i}]" for i in range(1, 11)], *_sensor_outputs(findings)]
    model = FMUModel(fmu)
    try:
        # from -600 s: a run's held pre-run lies before the data's first sample (time 0), where no effect acts
        df = model.simulate(start_time=-600.0, stop_time=1800.0, output_interval=5.0, outputs=names)
    finally:
        model.close()
    t = df["time"].to_numpy()
    # fouling: kht(t) = 1000*(1 - r*t/(1 + c*t)), t = max(time, 0)
    tt = np.maximum(t, 0.0)
    np.testing.assert_allclose(df["hx.kht_internal"], 1000.0 * (1 - 5e-6 * tt / (1 + 5e-4 * tt)), rtol=1e-9)
    # heat loss: UA*(mean hot-cell temperature - 293.15 K)
    mean_t1 = df[[f"hx.T1[{i}]" for i in range(1, 11)]].mean(axis=1)
    np.testing.assert_allclose(df["hx.Q_flow_loss_internal"], 200.0 * (mean_t1 - 293.15), rtol=1e-9)
    # ... and it comes out of the hot stream: m1*cp*(ThIn - ThOut) = Q_total + Q_loss near steady state
    # (1 kg/s, cp of water ~4180-4190 J/(kg K) at 50-90 degC; last 10 min, kht changes 0.3 % there)
    last = t > 1200.0
    hot = 1.0 * 4185.0 * (df["ThIn"] - df["ThOut"])[last]
    lost = (df["hx.Q_total"] + df["hx.Q_flow_loss_internal"])[last]
    np.testing.assert_allclose(hot, lost, rtol=0.01)
    _check_sensor_effects(df, patch, hx_spec, findings)


@pytest.mark.compile
def test_a_window_run_keeps_the_data_clock(hx_spec, hx_patch):
    """Every window of an estimation sees the model time = seconds from the data's first sample.

    A drift d*t/(1 + c*t), t = max(time, 0), added to TI-102 must read that at the data time on the window
    (which starts at the first sample: no run goes before it) and on a later window
    (which starts after a lead-in through the history) alike.
    """
    from trackingbox.estimation import Problem, WindowData, run_start, simulate_window

    patch, findings, fmu = hx_patch
    drift = next(f for f in findings if f.effect == "sensor-drift" and f.target == "TI-102")
    out = f"{prefix_for('sensor-drift', 'TI-102')}_y"
    problem = Problem(fmu, (), np.zeros(0), np.zeros(0), np.zeros(0), {}, {"y": out, "x": "ThOut"}, 10.0, 1200.0)
    ins = {"mHot_flow": 1.0, "ThIn": 363.15, "mCold_flow": 2.0, "TcIn": 283.15}
    for start, first in ((0.0, 0.0), (3000.0, 2400.0)):
        time = np.arange(first, start + 1800.0, 10.0)
        window = WindowData("w", start, start + 1800.0, time, {k: np.full(time.size, v) for k, v in ins.items()},
                            {"y": np.zeros(time.size), "x": np.zeros(time.size)}, int(round((start - first) / 10.0)))
        assert run_start(problem, window) == first  # never before the data's first sample
        sim = simulate_window(problem, window, np.zeros(0))
        d, c = drift.values["d"], drift.values["c"]
        np.testing.assert_allclose(sim["y"] - sim["x"], d * time / (1 + c * time), rtol=1e-9, atol=1e-9)


@pytest.mark.compile
def test_hp_patch_effects_act_as_explained(hp_spec, hp_patch):
    from trackingbox.fmu import FMUModel

    patch, findings, fmu = hp_patch
    names = ["T200.level", "T200.rho", "T200.A", "T200.m_flow_in", "T200.m_flow_out", "T200.m_flow_corr_total",
             "T200.m_flow_leak_internal", "T100.T", "T100.Q_flow_loss_internal", "HU300.kht_internal",
             "HEX300.kht_internal", *HP_TAGS.values(), *_sensor_outputs(findings)]
    model = FMUModel(fmu)
    try:
        df = model.simulate(stop_time=600.0, output_interval=1.0, outputs=names)
    finally:
        model.close()
    t = df["time"].to_numpy()
    # the modifier T200(use_leak = true) took effect: the leak flow is the parameter
    np.testing.assert_allclose(df["T200.m_flow_leak_internal"], 0.004, rtol=1e-12)
    # mass balance of T200: rho*A*dlevel/dt = in - out + corr - k (dlevel/dt by central differences)
    rate = df["T200.rho"] * 0.3 * np.gradient(df["T200.level"].to_numpy(), t)
    balance = df["T200.m_flow_in"] - df["T200.m_flow_out"] + df["T200.m_flow_corr_total"] - 0.004
    inner = slice(5, -5)
    np.testing.assert_allclose(rate[inner], balance[inner], atol=2e-4)
    np.testing.assert_allclose(df["T100.Q_flow_loss_internal"], 200.0 * (df["T100.T"] - 293.15), rtol=1e-9)
    np.testing.assert_allclose(df["HU300.kht_internal"], 1050.0 * (1 - 5e-6 * t / (1 + 5e-4 * t)), rtol=1e-9)
    np.testing.assert_allclose(df["HEX300.kht_internal"], 1000.0 * (1 - 5e-6 * t / (1 + 5e-4 * t)), rtol=1e-9)
    _check_sensor_effects(df, patch, hp_spec, findings)


@pytest.mark.compile
def test_hooks_off_change_nothing(fmu_cache, hx_spec, tmp_path):
    """The twin with its hooks off equals the patched twin with every effect at zero."""
    from trackingbox.diagnose.library import compile_patch
    from trackingbox.fmu import FMUModel, read_info

    info = read_info(fmu_cache(HX))
    names = {v.name for v in info.variables}
    assert not any(n.endswith(("m_flow_leak_in", "Q_flow_loss_in")) for n in names)  # the conditional inputs are gone
    assert sorted(info.tunable_parameters) == sorted(
        ["hx.kht", "hx.A", "hx.V1", "hx.V2", "hx.dp1_nominal", "hx.dp2_nominal", "hx.m1_flow_nominal",
         "hx.m2_flow_nominal", "hotOut.p", "coldOut.p"])
    zero = render_patch(hx_spec, [Finding("heat-loss", "hx", {"UA": 0.0}), Finding("fouling", "hx", {"r": 0.0})])
    patched = compile_patch(zero, tmp_path).fmu
    runs = []
    for fmu in (fmu_cache(HX), patched):
        model = FMUModel(fmu)
        try:
            runs.append(model.simulate(stop_time=600.0, output_interval=10.0, outputs=["ThOut", "TcOut"]))
        finally:
            model.close()
    np.testing.assert_allclose(runs[0][["ThOut", "TcOut"]], runs[1][["ThOut", "TcOut"]], atol=1e-6)


@pytest.mark.compile
def test_patched_spec_continues_on_the_patch(hp_spec, hp_patch, tmp_path):
    patch, _, fmu = hp_patch
    out = patched_spec(hp_spec, patch, tmp_path / "patched", fmu)
    spec = load_spec(out)
    check_against_fmu(spec)
    assert spec.outputs["TI-300"] == patch.outputs["TI-300"]
    assert spec.source.model == "TwinDiagnosed" and (tmp_path / "patched" / "TwinDiagnosed.mo").is_file()
    leak = spec.parameter("leak_T200_k")
    assert (leak.start, leak.min, leak.max) == (0.004, 0.0, 0.03)
    shutil.rmtree(tmp_path / "patched")


@pytest.mark.compile
def test_documented_user_entry_compiles_and_acts(hp_spec, tmp_path):
    """docs/examples/effects/leak-sqrt (the example of docs/diagnose-effects.md) on T200."""
    from trackingbox.diagnose.library import compile_patch
    from trackingbox.fmu import FMUModel

    folder = Path(__file__).resolve().parents[1] / "docs" / "examples" / "effects"
    effects = load_effects([folder])
    assert targets(effects["leak-sqrt"], hp_spec) == ["T100", "T200", "T400"]
    patch = render_patch(hp_spec, [Finding("leak-sqrt", "T200", {"c": 0.005})], effects=effects)
    model = FMUModel(compile_patch(patch, tmp_path).fmu)
    try:
        df = model.simulate(stop_time=300.0, output_interval=10.0,
                            outputs=["T200.level", "T200.m_flow_leak_internal"])
    finally:
        model.close()
    np.testing.assert_allclose(df["T200.m_flow_leak_internal"], 0.005 * np.sqrt(df["T200.level"]), rtol=1e-9)


@pytest.mark.compile
def test_fluid_validation_hooks(fmu_cache):
    """Fluid.Validation.DiagnosisHooks: equal in- and outflow, so the level falls at leak/(rho*A)."""
    from trackingbox.fmu import FMUModel

    model = FMUModel(fmu_cache("TrackingBox.Fluid.Validation.DiagnosisHooks"))
    try:
        df = model.simulate(stop_time=600.0, output_interval=5.0,
                            outputs=["tank.level", "tank.rho", "heater.kht_internal", "hex.Q_flow_loss_internal"])
    finally:
        model.close()
    t = df["time"].to_numpy()
    rate = np.gradient(df["tank.level"].to_numpy(), t)
    np.testing.assert_allclose(rate[2:-2], (-0.01 / (df["tank.rho"] * 0.2))[2:-2], rtol=1e-3)
    np.testing.assert_allclose(df["heater.kht_internal"], 1050.0 * (1 - 1e-4 * t), rtol=1e-9)
    np.testing.assert_allclose(df["hex.Q_flow_loss_internal"], 2000.0)


@pytest.mark.compile
def test_one_hook_driven_once(hp_spec):
    folder = Path(__file__).resolve().parents[1] / "docs" / "examples" / "effects"
    effects = load_effects([folder])
    with pytest.raises(SpecError, match=r"already uses the hook 'use_leak' of 'T200'"):
        render_patch(hp_spec, [Finding("leak", "T200", {}), Finding("leak-sqrt", "T200", {})], effects=effects)
